"""Multi-span bridges: supports, piers, default targets, deflection shapes."""
import time

import numpy as np
import pytest

from common.errors import InputError
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.bridge import continuous_deflection, deck_mesh, pier_meshes

THREE = BridgeModel(spans_m=(39.9, 39.9, 39.9))


def test_single_span_default_is_todays_bridge():
    m = BridgeModel()
    assert m.spans_m == (40.0,) and m.support_x_m == (0.0, 40.0) and m.span_m == 40.0 and m.n_spans == 1
    assert [t.id for t in m.targets] == ["R1", "R2", "R3", "R4", "M1", "M2", "M3", "M4", "M5"]
    assert len(pier_meshes(m)) == 2


def test_three_spans_have_four_piers_and_the_expected_targets():
    m = THREE
    assert m.n_spans == 3 and m.length_m == pytest.approx(119.7) and m.span_m == pytest.approx(119.7)
    np.testing.assert_allclose(m.support_x_m, (0.0, 39.9, 79.8, 119.7))
    assert len(pier_meshes(m)) == 4
    ref = [t for t in m.targets if t.group == "reference"]
    meas = [t for t in m.targets if t.group == "measurement"]
    assert [t.id for t in ref] == [f"R{k}" for k in range(1, 9)]
    assert [t.id for t in meas] == [f"M{k}" for k in range(1, 19)]
    face = m.pier_length_m / 2 + 0.001
    # end piers: two each on the inner face, at two heights and two positions across
    for ids, x, nx in ((("R1", "R2"), face, 1.0), (("R7", "R8"), 119.7 - face, -1.0)):
        a, b = (m.target(i) for i in ids)
        assert a.centre_m[0] == pytest.approx(x) and b.centre_m[0] == pytest.approx(x)
        assert a.normal == (nx, 0.0, 0.0) == b.normal
        assert a.centre_m[1] != b.centre_m[1] and a.centre_m[2] != b.centre_m[2]
    # inner piers: one on each face, facing into the adjoining spans
    for ids, x in ((("R3", "R4"), 39.9), (("R5", "R6"), 79.8)):
        west, east = (m.target(i) for i in ids)
        assert west.centre_m[0] == pytest.approx(x - face) and west.normal == (-1.0, 0.0, 0.0)
        assert east.centre_m[0] == pytest.approx(x + face) and east.normal == (1.0, 0.0, 0.0)
    # six deck targets at each midspan: 3 along x 2 girder lines
    for k, x0 in enumerate((0.0, 39.9, 79.8)):
        span_targets = meas[6 * k:6 * k + 6]
        xs = sorted({round(t.centre_m[0], 6) for t in span_targets})
        np.testing.assert_allclose(xs, [x0 + f * 39.9 for f in (0.4, 0.5, 0.6)])
        assert sorted({t.centre_m[1] for t in span_targets}) == [-1.5, 1.5]
        assert all(t.normal == (0.0, 0.0, -1.0) and t.centre_m[2] == pytest.approx(6.999) for t in span_targets)


def test_deck_layout_is_configurable():
    m = BridgeModel(spans_m=(30.0, 50.0), deck_width_m=9.0, deck_fractions=(0.25, 0.5, 0.75),
                    girder_lines_m=(-3.5, 0.0, 3.5))
    assert len([t for t in m.targets if t.group == "reference"]) == 6
    meas = [t for t in m.targets if t.group == "measurement"]
    assert len(meas) == 2 * 3 * 3
    assert {t.centre_m[1] for t in meas} == {-3.5, 0.0, 3.5}
    assert m.target("M10").centre_m[0] == pytest.approx(30.0 + 0.25 * 50.0)
    one = BridgeModel(deck_fractions=(0.5,), girder_lines_m=(-1.0, 1.0))
    assert [t.id for t in one.targets] == ["R1", "R2", "R3", "R4", "M1", "M2"]
    with pytest.raises(InputError, match="fractions"):
        BridgeModel(spans_m=(30.0, 30.0), deck_fractions=(0.0, 0.5))
    with pytest.raises(InputError, match="girder lines"):
        BridgeModel(spans_m=(30.0, 30.0), girder_lines_m=(4.0,))
    with pytest.raises(InputError, match="positive"):
        BridgeModel(spans_m=(30.0, -1.0))
    with pytest.raises(InputError, match="deflection_shape"):
        BridgeModel(deflection_shape="cubic")


@pytest.mark.parametrize("shape", ["sine", "continuous"])
def test_deflection_is_zero_at_every_support_and_the_amplitude_at_midspans(shape):
    m = BridgeModel(spans_m=(30.0, 45.0, 30.0), deflection_shape=shape)
    amps = (-0.004, -0.006, -0.003)
    np.testing.assert_allclose(m.deflection_m(np.array(m.support_x_m), amps), 0.0, atol=1e-15)
    np.testing.assert_allclose(m.deflection_m(np.array([15.0, 52.5, 90.0]), amps), amps, atol=1e-12)
    assert m.deflection_m(-1.0, amps) == 0.0 and m.deflection_m(106.0, amps) == 0.0
    one_value = m.deflection_m(np.array([15.0, 52.5, 90.0]), -0.002)
    np.testing.assert_allclose(one_value, -0.002, atol=1e-12)


def test_half_sine_per_span_and_continuous_beam_smooth_over_inner_piers():
    sine = BridgeModel(spans_m=(30.0, 45.0), deflection_shape="sine")
    x = np.array([7.5, 30.0 + 45.0 / 3])
    np.testing.assert_allclose(sine.deflection_m(x, (-0.004, -0.006)),
                               [-0.004 * np.sin(np.pi / 4), -0.006 * np.sin(np.pi / 3)])
    cont = BridgeModel(spans_m=(30.0, 45.0), deflection_shape="continuous")
    h = 1e-5
    for model, smooth in ((cont, True), (sine, False)):
        left = (model.deflection_m(30.0, (-0.004, -0.006)) - model.deflection_m(30.0 - h, (-0.004, -0.006))) / h
        right = (model.deflection_m(30.0 + h, (-0.004, -0.006)) - model.deflection_m(30.0, (-0.004, -0.006))) / h
        assert (abs(left - right) < 1e-7) == smooth
    # equal spans equally loaded: the classical two-span beam, its maximum sag 0.4215 L from the end support
    xs = np.linspace(0.0, 40.0, 40001)
    w = continuous_deflection((40.0, 40.0), (-0.005, -0.005), xs)
    assert xs[np.argmin(w)] == pytest.approx(0.4215 * 40.0, abs=0.01)


def test_scene_deflects_deck_targets_of_every_span():
    setup = ScannerSetup((60.0, -15.0, 1.5), heading_deg=40.0)
    amps = (-0.004, -0.006, -0.003)
    scene = BridgeScene(THREE, EpochConditions(span_displacements_m=amps), setup)
    truth = scene.truth()
    for t in truth.targets:
        x = THREE.target(t.id).centre_m[0]
        want = float(THREE.deflection_m(x, amps)) if t.group == "measurement" else 0.0
        assert t.vertical_displacement_m == pytest.approx(want, abs=1e-15)
    assert truth.spans_m == THREE.spans_m and truth.span_displacements_m == amps
    assert truth.target("M3").vertical_displacement_m == pytest.approx(-0.004 * np.sin(0.6 * np.pi))
    v, _ = deck_mesh(THREE, amps)
    assert v.shape == (600 * 4, 3)
    with pytest.raises(InputError, match="3 spans"):
        BridgeScene(THREE, EpochConditions(span_displacements_m=(-0.004, -0.006)), setup)


def test_three_span_coarse_scan_from_one_end_is_quick_and_sees_the_bridge():
    setup = ScannerSetup((-8.0, -14.0, 1.5), heading_deg=20.0)
    t0 = time.perf_counter()
    scene = BridgeScene(THREE, EpochConditions(), setup)
    scan, truth = scene.scan(scene.coarse_window(step_deg=0.05), rng=np.random.default_rng(0))
    seconds = time.perf_counter() - t0
    assert seconds < 60.0
    assert len(scan) > 300_000
    far = scan.xyz_socs @ scene.setup.rotation.T + np.asarray(setup.position_m)
    assert far[:, 0].max() > 115.0  # the last pier is in view

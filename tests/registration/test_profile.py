"""The span profile against the simulator's truth: deck underside only, per girder line, σ with the registration."""
from __future__ import annotations

import numpy as np
import pytest

from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.bridge import Target
from registration.errors import InputError
from registration.profile import RegistrationSigma, girder_lines, span_profile, underside_points, voxel_normals

SAG_M = -0.0065
#: Registration of the second epoch: 0.1 mm at the pier targets' centroid, 5 µrad of rotation.
REGISTRATION = RegistrationSigma(1.0e-4, 5.0e-6, (20.0, 0.0))


def _model(width_m: float) -> BridgeModel:
    """A bridge of the given deck width whose first girder line runs 0.3 m from the deck edge.

    A band 0.5 m either side of that line reaches past the edge, where the lowest centimetres of the side face
    the scanner sees lie at the underside's height.
    """
    base = BridgeModel(deck_width_m=width_m)
    hw = width_m / 2
    ys = (-(hw - 0.3), hw - 1.0, -(hw - 0.3), hw - 1.0, -(hw - 0.3))
    meas = [Target(f"M{k + 1}", "measurement", (f * base.span_m, y, base.deck_bottom_m - 0.001), (0, 0, -1))
            for k, (f, y) in enumerate(zip((0.2, 0.35, 0.5, 0.65, 0.8), ys, strict=False))]
    return base.with_targets([t for t in base.targets if t.group == "reference"] + meas)


def _epochs(model: BridgeModel, seed: int) -> list[np.ndarray]:
    """Two coarse scans (0.06 degrees) in the bridge frame: unloaded, then a 6.5 mm midspan sag.

    Both stations stand beside the bridge (y < 0): each sees the deck's near side face.
    """
    rng = np.random.default_rng(seed)
    out = []
    for sag in (0.0, SAG_M):
        setup = ScannerSetup((rng.uniform(10, 30), rng.uniform(-14, -9), 1.5), heading_deg=rng.uniform(0, 360))
        scene = BridgeScene(model, EpochConditions(midspan_displacement_m=sag), setup)
        scan, _ = scene.scan(scene.coarse_window(step_deg=0.06), rng=rng)
        out.append(scan.xyz_socs @ setup.rotation.T + np.asarray(setup.position_m))
    return out


def _lines(model: BridgeModel):
    meas = [t for t in model.targets if t.group == "measurement"]
    return girder_lines(np.array([t.centre_m[:2] for t in meas]), np.array([t.centre_m[2] for t in meas]))


@pytest.mark.parametrize("width_m, seed", [(4.0, 901), (8.0, 902)])
def test_a_sag_is_measured_within_three_sigma_on_both_girder_lines(width_m, seed):
    model = _model(width_m)
    a, b = _epochs(model, seed)
    hw = width_m / 2
    side = (np.abs(b[:, 1] + hw) < 0.02) & (b[:, 2] < model.deck_bottom_m + 0.15) & (b[:, 2] > model.deck_bottom_m - 0.01)
    assert side.sum() > 1000  # the trap is there: side-face points inside the old selection's band
    lines = _lines(model)
    assert len(lines) == 2
    prof = span_profile(a, b, lines, stations_m=(1.0, 39.0), registration=(None, REGISTRATION))
    assert not prof.notes
    for g in (0, 1):
        stations = [x.station_m for x in prof.bins if x.girder == g]
        assert stations == pytest.approx(np.arange(1.25, 40, 2.5))  # every station from the first pier to the last
    for x in prof.bins:
        truth = float(model.deflection_m(x.station_m, SAG_M))
        assert abs(x.change_m - truth) <= max(3 * x.sigma_change_m, 5e-4), (x, truth)
        assert x.sigma_registration_m >= REGISTRATION.sigma_translation_m  # the registration error is in the σ
        assert x.sigma_change_m > x.sigma_fit_m


def test_side_faces_are_not_underside():
    model = _model(4.0)
    _, b = _epochs(model, 903)
    lines = _lines(model)
    sel = underside_points(b, lines, band_m=0.15, half_width_m=0.5, max_tilt_deg=15.0)
    side = (np.abs(b[:, 1] + 2.0) < 0.01) & (b[:, 2] > model.deck_bottom_m + 0.03) & (b[:, 2] < model.deck_bottom_m + 0.15)
    assert side.sum() > 500 and not sel[side].any()
    under = (np.abs(b[:, 2] - model.deck_bottom_m) < 0.03) & (np.abs(b[:, 1] - lines[1].offset_m) < 0.5) & \
        (b[:, 0] > 5) & (b[:, 0] < 35)
    assert sel[under].mean() > 0.95


def test_voxel_normals_of_two_faces():
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(0, 2, 4000), rng.uniform(0, 2, 4000), rng.normal(0, 0.002, 4000)])
    wall = np.column_stack([rng.normal(3.1, 0.002, 4000), rng.uniform(0, 2, 4000), rng.uniform(0, 2, 4000)])
    n = voxel_normals(np.vstack([floor, wall]))
    fz, wx = np.abs(n[:4000, 2]), np.abs(n[4000:, 0])
    assert np.isnan(fz).mean() < 0.01 and np.isnan(wx).mean() < 0.01  # only edge voxels of a few points
    assert np.all(fz[np.isfinite(fz)] > 0.99) and np.all(wx[np.isfinite(wx)] > 0.99)


def test_registration_sigma_grows_with_the_lever():
    r = RegistrationSigma(1e-4, 1e-5, (20.0, 0.0))
    v = r.vertical_m(np.array([20.0, 40.0]), np.array([0.0, 0.0]))
    assert v[0] == pytest.approx(1e-4) and v[1] == pytest.approx(np.hypot(1e-4, 2e-4))


def test_bad_profile_input():
    lines = girder_lines(np.array([[10.0, 0.0]]), np.array([7.0]))
    pts = np.zeros((10, 3))
    with pytest.raises(InputError, match="girder line"):
        span_profile(pts, pts, (), stations_m=(0.0, 40.0))
    with pytest.raises(InputError, match="positive"):
        span_profile(pts, pts, lines, stations_m=(0.0, 40.0), bin_m=0.0)
    prof = span_profile(pts, pts, lines, stations_m=(0.0, 40.0))
    assert not prof.bins and prof.notes

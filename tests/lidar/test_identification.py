import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common.errors import ProcessingError
from lidar.identification import identify_reflectors
from lidar.layout import layout_from_model
from lidar.simulate import BridgeModel

MODEL = BridgeModel()


def scanner_view(rng, drop=(), extra=0):
    """Detections: the true centres in an arbitrary scanner frame, a few mm of noise."""
    rot = Rotation.from_euler("zyx", [rng.uniform(0, 360), 0.3, -0.2], degrees=True).as_matrix()
    t = rng.normal(0, 20, 3)
    ids = [tg.id for tg in MODEL.targets if tg.id not in drop]
    xyz = np.array([MODEL.target(i).centre_m for i in ids]) @ rot.T + t + rng.normal(0, 0.005, (len(ids), 3))
    extras = xyz[:extra] + rng.uniform(0.3, 2.0, (extra, 3)) if extra else np.zeros((0, 3))
    order = rng.permutation(len(ids) + extra)
    allx = np.vstack([xyz, extras])[order]
    names = (ids + [None] * extra)
    return allx, [names[k] for k in order]


def test_identifies_in_any_frame_with_missing_and_extra():
    rng = np.random.default_rng(3)
    layout = layout_from_model(MODEL, noise_m=0.03, rng=rng)
    det, names = scanner_view(rng, drop=("M2", "R3"), extra=3)
    ident = identify_reflectors(det, layout)
    for m in ident.matches:
        if m.detection is not None:
            assert names[m.detection] == m.id
    assert set(ident.missing) == {"M2", "R3"}
    assert len(ident.extra_detections) == 3
    assert ident.rms_m < 0.08


def test_predicted_positions_come_from_the_fit():
    rng = np.random.default_rng(4)
    layout = layout_from_model(MODEL, noise_m=0.0)
    det, names = scanner_view(rng, drop=("M5",))
    ident = identify_reflectors(det, layout)
    m5 = ident.match("M5")
    assert m5.predicted and m5.residual_m is None
    pred = layout.xyz[layout.index("M5")] @ ident.rotation.T + ident.translation
    np.testing.assert_allclose(m5.xyz_socs, pred)


def test_too_few_or_unrelated_detections():
    layout = layout_from_model(MODEL)
    with pytest.raises(ProcessingError, match="at least 3"):
        identify_reflectors(np.zeros((2, 3)), layout)
    rng = np.random.default_rng(1)
    with pytest.raises(ProcessingError, match="do not match the layout"):
        identify_reflectors(rng.uniform(0, 0.5, (6, 3)), layout)


def _twin_girder_layout():
    """A 40 m span: two coplanar reference targets on each pier (0.5 m sideways, 1.5 m up), six deck targets."""
    from lidar.layout import Layout

    ids = ("R1", "R2", "R3", "R4", "M1", "M2", "M3", "M4", "M5", "M6")
    groups = ("reference",) * 4 + ("measurement",) * 6
    xyz = np.array([[0, 0, 0], [0, 0.5, 1.5], [40, 0, 0], [40, 0.5, 1.5],
                    [10, -2.4, 6], [20, -2.4, 6], [30, -2.4, 6], [10, 1.2, 6], [20, 1.2, 6], [30, 1.2, 6]], float)
    return Layout(ids=ids, groups=groups, xyz=xyz, diameters_m=np.full(10, 0.05))


@pytest.mark.parametrize("heading", [0.0, 37.0, 90.0, 145.0, 200.0, 263.0, 311.0])
def test_symmetric_coplanar_references_without_deck_targets_are_not_turned_upside_down(heading):
    from lidar.identification import tilt_deg

    layout = _twin_girder_layout()
    rng = np.random.default_rng(int(heading))
    rot = Rotation.from_euler("zyx", [heading, 0.01, -0.01], degrees=True).as_matrix()  # a levelled scanner
    refs = layout.xyz[:4] @ rot.T + np.array([-20.0, 14.0, -1.5]) + rng.normal(0, 0.003, (4, 3))
    # the mirror solution fits the four references exactly as well: the geometry alone cannot decide
    axis = (layout.xyz[1] - layout.xyz[0]) / np.linalg.norm(layout.xyz[1] - layout.xyz[0])
    flip = Rotation.from_rotvec(np.pi * axis).as_matrix()
    c = layout.xyz[:4].mean(axis=0)
    mirrored = (layout.xyz[:4] - c) @ flip.T + c
    assert np.allclose(np.sort(np.linalg.norm(mirrored[:, None] - layout.xyz[None, :4], axis=2).min(axis=1)), 0,
                       atol=1e-9)
    assert tilt_deg(flip) > 30
    ident = identify_reflectors(refs, layout)
    for k, rid in enumerate(("R1", "R2", "R3", "R4")):
        assert ident.match(rid).detection == k
    assert ident.tilt_deg < 0.5
    truth_m2 = layout.xyz[5] @ rot.T + np.array([-20.0, 14.0, -1.5])
    assert np.linalg.norm(np.array(ident.match("M2").xyz_socs) - truth_m2) < 0.05  # windows go where the deck is


def test_an_unlevelled_set_up_can_still_be_identified():
    layout = _twin_girder_layout()
    rot = Rotation.from_euler("zyx", [30, 25, 10], degrees=True).as_matrix()  # no compensator, tilted 27 deg
    det = layout.xyz @ rot.T + 5.0
    ident = identify_reflectors(det, layout, max_tilt_deg=None)
    assert ident.rms_m < 1e-6 and ident.tilt_deg > 20
    ident = identify_reflectors(det, layout)  # levelled solutions are preferred, none exists: the best fit stands
    assert ident.rms_m < 1e-6


def test_a_genuine_tie_is_refused_not_guessed():
    # the demo's pier targets alone are symmetric under a half turn about the vertical: a levelled scanner
    # seeing only them cannot tell R1 from R3
    layout = layout_from_model(MODEL, noise_m=0.0)
    refs = [t for t in MODEL.targets if t.group == "reference"]
    rot = Rotation.from_euler("z", 35, degrees=True).as_matrix()
    det = np.array([t.centre_m for t in refs]) @ rot.T + np.array([5.0, -12.0, -1.5])
    with pytest.raises(ProcessingError, match="two identifications fit the 4 detected reflectors equally well"):
        identify_reflectors(det, layout)
    # one deck target seen breaks the tie
    m1 = np.array(MODEL.target("M1").centre_m) @ rot.T + np.array([5.0, -12.0, -1.5])
    ident = identify_reflectors(np.vstack([det, m1]), layout)
    assert ident.match("R1").detection == 0 and ident.match("M1").detection == 4


def test_the_surveyors_station_settles_a_tie_and_a_wrong_one_cannot_force_it():
    layout = layout_from_model(MODEL, noise_m=0.0)
    refs = [t for t in MODEL.targets if t.group == "reference"]
    rot = Rotation.from_euler("z", 35, degrees=True).as_matrix()
    shift = np.array([5.0, -12.0, -1.5])
    det = np.array([t.centre_m for t in refs]) @ rot.T + shift
    station = -rot.T @ shift  # where this scanner stands in the layout's frame
    ident = identify_reflectors(det, layout, station_xy=station[:2] + (2.0, -1.5))  # roughly right
    assert ident.match("R1").detection == 0 and ident.rms_m < 1e-6
    ident = identify_reflectors(det, layout, station_xy=(2 * 20.0 - station[0], -station[1]))  # the other end
    assert ident.match("R1").detection != 0  # the surveyor's word is taken: the mirror solution
    with pytest.raises(ProcessingError, match="station_xy"):  # midway between the two: still a tie
        identify_reflectors(det, layout, station_xy=(20.0, 0.0))


def test_a_layout_with_another_up_axis_is_declared_and_levelled():
    layout = _twin_girder_layout()
    from lidar.layout import Layout

    yup = Layout(ids=layout.ids, groups=layout.groups, xyz=layout.xyz[:, [0, 2, 1]] * np.array([1, 1, -1]),
                 diameters_m=layout.diameters_m)  # a surveying frame with y up
    rot = Rotation.from_euler("z", 200, degrees=True).as_matrix()
    det = layout.xyz[:4] @ rot.T + 7.0  # only the four coplanar pier targets, levelled scanner
    ident = identify_reflectors(det, yup, up_layout=(0.0, 1.0, 0.0))
    assert ident.tilt_deg < 0.5
    assert [ident.match(r).detection for r in ("R1", "R2", "R3", "R4")] == [0, 1, 2, 3]


def _periodic_case(seed):
    """A three-span bridge seen in part: one inner-pier target and the first span's deck targets (a shift by
    one span fits them as well), in a levelled scanner frame near the first end pier."""
    model = BridgeModel(spans_m=(39.9, 39.9, 39.9))
    rng = np.random.default_rng(seed)
    layout = layout_from_model(model, noise_m=0.03, rng=rng)
    rot = Rotation.from_euler("z", rng.uniform(0, 360), degrees=True).as_matrix()
    station = np.array([-4.0, -12.0, 1.5])
    seen = ["R3", "M1", "M2", "M3", "M4", "M5"]
    true = {t.id: (np.asarray(t.centre_m) - station) @ rot for t in model.targets}
    det = np.array([true[i] for i in seen]) + rng.normal(0, 0.01, (len(seen), 3))
    return layout, det, seen, true


def _evidence_from(true, dark_radius=0.3):
    """What the coarse scan would say: a target where one is, the scan sees through empty air elsewhere."""
    def evidence(xyz):
        d = min(np.linalg.norm(xyz - p) for p in true.values())
        return True if d < dark_radius else "through"
    return evidence


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_repeating_layout_is_told_apart_by_the_coarse_scan_or_refused(seed):
    layout, det, seen, true = _periodic_case(seed)
    with pytest.raises(ProcessingError, match="equally well"):
        identify_reflectors(det, layout)  # without evidence: a guess either way, so no answer
    ident = identify_reflectors(det, layout, evidence=_evidence_from(true))
    got = {m.id for m in ident.matches if m.detection is not None}
    assert got == set(seen)
    for m in ident.matches:
        if m.detection is None:  # the predicted positions are the true ones, not a span away
            assert np.linalg.norm(np.asarray(m.xyz_socs) - true[m.id]) < 0.2

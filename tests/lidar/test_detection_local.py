"""Detection by local contrast: targets on concrete near the intensity ceiling, clipped plateaus, missing reasons."""
import numpy as np

from lidar.angles import direction_from_angles, spherical_from_xyz
from lidar.detection import DetectionResult, auto_threshold, detect_reflectors, local_background
from lidar.guided_detection import missing_note, missing_reasons, recover_predicted
from lidar.identification import Identification, TargetMatch
from lidar.layout import layout_from_model
from lidar.pipeline import analyse_coarse, plan_from_coarse
from lidar.reflectance_map import reflectance_map
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup

STEP = 0.05
WALL_M = 6.0  # a wall this far along x: a 50 mm disc spans about 10 cells
NEAR_TARGET = (90.0, -10.0)  # (theta, phi) of a target on the bright (near-ceiling) concrete
FAR_TARGET = (90.0, 10.0)  # ... and of one on dim concrete
PLATEAU = ((100.0, 108.0), (-18.0, -5.0))  # a patch of concrete clipped at the ceiling


def _wall(seed=0):
    """A wall x = 6 m: concrete at 0.9 (phi < 0, near the ceiling) and 0.15, a clipped patch, two clipped discs."""
    rng = np.random.default_rng(seed)
    t, p = np.meshgrid(np.arange(75.0, 112.0, STEP / 2), np.arange(-20.0, 20.0, STEP / 2), indexing="ij")
    t, p = t.ravel(), p.ravel()
    d = direction_from_angles(t, p)
    xyz = d * (WALL_M / d[:, 0])[:, None]
    inten = np.where(p < 0, 0.9, 0.15) + rng.normal(0, 0.01, len(t))
    (t0, t1), (p0, p1) = PLATEAU
    inten[(t >= t0) & (t < t1) & (p >= p0) & (p < p1)] = 1.0
    centres = {}
    for name, (tc, pc) in (("near", NEAR_TARGET), ("far", FAR_TARGET)):
        c = direction_from_angles(np.array([tc]), np.array([pc]))[0]
        c = c * WALL_M / c[0]
        centres[name] = c
        inten[np.linalg.norm(xyz - c, axis=1) < 0.025] = 1.0
    return reflectance_map(xyz, np.clip(inten, 0.0, 1.0), step_deg=STEP), centres


def test_targets_on_bright_and_dim_concrete_are_found_and_a_clipped_patch_is_not():
    rmap, centres = _wall()
    det = detect_reflectors(rmap)
    found = det.xyz()
    for c in centres.values():
        assert np.min(np.linalg.norm(found - c, axis=1)) < 0.02
    assert len(det.detections) == 2  # the clipped patch (and its edges) is no target
    # the one threshold over the whole map cannot do it: the bright concrete is above it or the targets below
    glob = detect_reflectors(rmap, threshold=auto_threshold(rmap.max_intensity))
    near = [d for d in glob.detections if np.linalg.norm(np.asarray(d.xyz_socs) - centres["near"]) < 0.02]
    assert not near


def test_the_local_background_ignores_a_target_and_follows_the_surface():
    rmap, _ = _wall()
    bg, sigma = local_background(rmap.max_intensity, rmap.step_deg)
    row, col = (int(round(float(v[0]))) for v in rmap.cells_of(np.array([NEAR_TARGET[0]]), np.array([NEAR_TARGET[1]])))
    assert abs(bg[row, col] - 0.9) < 0.03  # the disc (10 cells wide) does not raise its own background
    row, col = (int(round(float(v[0]))) for v in rmap.cells_of(np.array([FAR_TARGET[0]]), np.array([FAR_TARGET[1]])))
    assert abs(bg[row, col] - 0.15) < 0.03
    assert 0.003 < float(np.nanmedian(sigma)) < 0.03  # about the noise of the maximum of a few points


def _predicted(*xyz_by_id):
    matches = tuple(TargetMatch(i, "measurement", tuple(float(v) for v in x), None, None) for i, x in xyz_by_id)
    return Identification(matches, np.eye(3), np.zeros(3), 0.01, ())


def _at(theta, phi, rng=WALL_M):
    d = direction_from_angles(np.array([theta]), np.array([phi]))[0]
    return d * rng / d[0]


def test_missing_targets_get_their_reason_in_one_line():
    rmap, centres = _wall()
    det = DetectionResult((), (), 1.2, STEP)  # a threshold above the scale's top, as on a dB map
    ident = _predicted(("M1", _at(104.0, -10.0)), ("M2", _at(90.0, 60.0)), ("M3", _at(95.0, 12.0)),
                       ("M4", _at(90.0, 5.0) * 0.5))
    why = missing_reasons(rmap, det, ident)
    assert "ceiling" in why["M1"]
    assert why["M2"] == "outside the coarse scan"
    assert why["M3"].startswith("not brighter than its surroundings")
    assert why["M4"].startswith("a bright spot there lies at") or "ceiling" not in why["M4"]
    note = missing_note(why, 9)
    assert "\n" not in note and note.startswith("the coarse scan did not find 4 of 9") and "M3 (not brighter" in note
    assert missing_note({}, 9) is None


def test_the_guided_look_takes_a_clipped_target_when_the_threshold_lies_above_the_top():
    """On a dB map the whole-map threshold may exceed 1: a clipped target on concrete at 0.9 is still taken."""
    rmap, centres = _wall()
    det = DetectionResult((), (), 1.2, STEP)
    ident = _predicted(("M1", centres["near"] + np.array([0.0, 0.03, -0.02])),
                       ("M2", _at(95.0, 12.0)))  # nothing there: nothing invented
    det2, ident2 = recover_predicted(rmap, det, ident)
    m1 = ident2.match("M1")
    assert not m1.predicted and det2.detections[m1.detection].guided
    assert np.linalg.norm(np.asarray(m1.xyz_socs) - centres["near"]) < 0.03
    assert ident2.match("M2").predicted
    _, _, r = spherical_from_xyz(np.asarray(m1.xyz_socs)[None])
    assert abs(float(r[0]) - np.linalg.norm(centres["near"])) < 0.05


def test_the_coarse_analysis_says_which_target_is_missing_and_why():
    model = BridgeModel()
    scene = BridgeScene(model, EpochConditions(occluded=("M2",)), ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0))
    coarse, _ = scene.scan(scene.coarse_window(0.06), rng=np.random.default_rng(3))
    layout = layout_from_model(model, noise_m=0.02)
    a = analyse_coarse(coarse, layout)
    assert a.identification.missing == ("M2",)
    assert a.missing_why["M2"].startswith("hidden behind something")
    assert a.missing_note.startswith("the coarse scan did not find 1 of 9 target(s)") and "M2 (hidden" in a.missing_note
    assert a.missing_note in plan_from_coarse(a, layout).warnings

import numpy as np
import pytest

from common.errors import InputError
from lidar.angles import spherical_from_xyz, window_around
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup

SETUP = ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0, pitch_deg=0.03, roll_deg=-0.02)


def fine_window(truth_target, half=0.12, step=0.006):
    t, p, _ = spherical_from_xyz(np.array([truth_target.centre_socs_m]))
    return window_around(t[0], p[0], half, half, step, step)


def test_truth_frames_are_consistent():
    scene = BridgeScene(BridgeModel(), EpochConditions(midspan_displacement_m=-0.01), SETUP)
    truth = scene.truth()
    pose = truth.scanner_pose
    for t in truth.targets:
        back = pose[:3, :3] @ np.asarray(t.centre_socs_m) + pose[:3, 3]
        np.testing.assert_allclose(back, t.centre_bridge_m, atol=1e-12)
    m3 = truth.target("M3")
    assert m3.vertical_displacement_m == pytest.approx(-0.01)
    assert truth.target("R1").vertical_displacement_m == 0.0
    assert truth.target("M1").vertical_displacement_m == pytest.approx(-0.01 * np.sin(0.2 * np.pi))


def test_coarse_scan_covers_every_target():
    scene = BridgeScene(BridgeModel(), EpochConditions(), SETUP)
    scan, truth = scene.scan(scene.coarse_window(step_deg=0.05), rng=np.random.default_rng(0))
    assert len(scan) > 500_000
    assert all(t.points_on_target >= 2 for t in truth.targets)
    assert scan.intensity.dtype == np.float32


def test_fine_scan_centroid_matches_truth_and_noise_model():
    scene = BridgeScene(BridgeModel(), EpochConditions(), SETUP)
    truth = scene.truth()
    r2 = truth.target("R2")
    scan, truth = scene.scan(fine_window(r2), rng=np.random.default_rng(1))
    bright = scan.intensity > 0.45
    n = np.count_nonzero(bright)
    assert n == pytest.approx(truth.target("R2").points_on_target, rel=0.15)
    centroid = scan.xyz_socs[bright].mean(axis=0)
    err = np.linalg.norm(centroid - np.asarray(r2.centre_socs_m))
    assert err < 5 * 0.005 / np.sqrt(n) + 0.5e-3
    # dull concrete around the target
    assert np.median(scan.intensity[~bright]) < 0.3


def test_noise_free_points_lie_on_the_disc_plane():
    scene = BridgeScene(BridgeModel(), EpochConditions(), SETUP)
    m3 = scene.truth().target("M3")
    scan, _ = scene.scan(fine_window(m3), rng=np.random.default_rng(2), range_noise_m=0.0)
    on = scan.intensity > 0.45
    offsets = (scan.xyz_socs[on] - np.asarray(m3.centre_socs_m)) @ np.asarray(m3.normal_socs)
    assert np.max(np.abs(offsets)) < 1e-5
    radial = np.linalg.norm(scan.xyz_socs[on] - np.asarray(m3.centre_socs_m), axis=1)
    assert radial.max() < 0.025 + 0.01


def test_occluded_target_gets_no_points_and_removed_target_is_gone():
    scene = BridgeScene(BridgeModel(), EpochConditions(occluded=("M2",), removed=("R3",)), SETUP)
    m2 = scene.truth().target("M2")
    scan, truth = scene.scan(fine_window(m2, half=0.3, step=0.02), rng=np.random.default_rng(3))
    assert truth.target("M2").points_on_target == 0
    assert "R3" not in {t.id for t in truth.targets}
    assert np.max(scan.intensity) < 0.45


def test_cable_tie_adds_bright_points_below_the_target():
    base = BridgeScene(BridgeModel(), EpochConditions(), SETUP)
    tie = BridgeScene(BridgeModel(), EpochConditions(cable_ties=("R1",)), SETUP)
    r1 = base.truth().target("R1")
    w = fine_window(r1, half=0.2, step=0.006)
    a, _ = base.scan(w, rng=np.random.default_rng(4))
    b, _ = tie.scan(w, rng=np.random.default_rng(4))
    extra = np.count_nonzero(b.intensity > 0.45) - np.count_nonzero(a.intensity > 0.45)
    assert extra > 20
    bright_b = b.xyz_socs[b.intensity > 0.45]
    assert bright_b[:, 2].min() < r1.centre_socs_m[2] - 0.035


def test_moved_target_truth_and_validation():
    scene = BridgeScene(BridgeModel(), EpochConditions(moved_targets={"R4": (0, 0, 0.005)}), SETUP)
    assert scene.truth().target("R4").moved
    assert scene.truth().target("R4").vertical_displacement_m == pytest.approx(0.005)
    with pytest.raises(InputError, match="unknown targets"):
        BridgeScene(BridgeModel(), EpochConditions(occluded=("Q9",)), SETUP)


def test_a_pier_shift_moves_that_pier_and_its_targets_not_the_deck():
    from lidar.simulate.files import conditions_from_dict, conditions_to_dict

    cond = EpochConditions(pier_shifts={1: (0.003, 0.0, 0.0)})
    scene = BridgeScene(BridgeModel(), cond, SETUP)
    moved = {d.target.id: d.displacement for d in scene.discs}
    assert np.allclose(moved["R3"], (0.003, 0, 0)) and np.allclose(moved["R4"], (0.003, 0, 0))
    assert np.allclose(moved["R1"], 0) and np.allclose(moved["M3"], 0)
    r3 = scene.truth().target("R3")
    assert r3.centre_bridge_m[0] == pytest.approx(BridgeModel().targets[2].centre_m[0] + 0.003)
    assert conditions_from_dict(conditions_to_dict(cond)).pier_shifts == {1: (0.003, 0.0, 0.0)}
    with pytest.raises(InputError, match="piers"):
        BridgeScene(BridgeModel(), EpochConditions(pier_shifts={5: (0.003, 0.0, 0.0)}), SETUP)

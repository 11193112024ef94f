"""The simulator's defaults stay as they were: fingerprints of today's outputs, recorded before any new effect.

Every new effect (multi-span, strain, atmosphere, range walk, clipping, drift, time stamps) is off by default
and draws no random numbers when off, so these files, truths and centroids must not change.

The outputs are compared through fingerprints with tolerances, not byte digests: the simulator's rotations and
projections go through BLAS and numpy's SIMD loops, whose last bits differ between CPUs (the centroid-level
observation differs in its last bits between OpenBLAS's Haswell and Sandybridge kernels on one machine), so a
digest pinned on one machine fails on another. A fingerprint holds what a changed default would move: the
point counts (exact), the mean and spread of the coordinates, ranges and intensities of all points and of the
bright (reflector) points, and the truths' target centres, to 1 um. The simulator is not chaotic: moving the
scanner by 1e-12 m moves every fingerprint value by about 1e-12 m, and a LAS coordinate rounded the other way
(10 um) moves a mean by 1e-11 m; but Open3D casts its rays in single precision, whose SIMD paths differ between
CPUs by a few micrometres a point at 20 m, and a mean over a scan moved by 3-7e-8 m between two machines of
ours (the tolerance was 10 nm then). Another random stream, or any effect turned on, moves the values by
tens of micrometres or more (tested below).

Regenerate the pins (only when a default is meant to change, saying why in the commit):
``python -m tests.lidar.simulate.test_defaults_pinned``.
"""
import json
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate import centroids as sc
from lidar.simulate.epochs import fine_epoch, plan_from_truth
from lidar.simulate.files import simulate_coarse, simulate_fine

PINS = Path(__file__).parents[2] / "data" / "simulator_default_pins.json"
SETUP = ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0, pitch_deg=0.03, roll_deg=-0.02)
CONDITIONS = {
    "plain": EpochConditions(midspan_displacement_m=-0.004),
    "traps": EpochConditions(midspan_displacement_m=-0.006, moved_targets={"R4": (0, 0, 0.003)}, occluded=("M2",),
                             cable_ties=("R1", "M4"), removed=("R3",), saturated=True),
}
#: Absolute tolerance of a fingerprint's float (metres; intensities in [0, 1]); counts are exact.
TOL_M = 1e-6


def points_fingerprint(xyz: np.ndarray, intensity: np.ndarray) -> dict:
    """Count, mean and spread of coordinates, range and intensity (in [0, 1]), for all and bright points."""
    out = {}
    for name, keep in (("all", np.ones(len(xyz), bool)), ("bright", intensity >= 0.5)):
        p, rng = xyz[keep], np.linalg.norm(xyz[keep], axis=1)
        out[name] = {"n": int(keep.sum()), "mean_m": p.mean(axis=0).tolist(), "std_m": p.std(axis=0).tolist(),
                     "range_mean_m": float(rng.mean()), "range_std_m": float(rng.std()),
                     "intensity_mean": float(intensity[keep].mean()), "intensity_std": float(intensity[keep].std())}
    return out


def las_fingerprint(path: Path) -> dict:
    las = laspy.read(path)
    hdr = las.header
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    return {"scales": list(map(float, hdr.scales)), "offsets": list(map(float, hdr.offsets)),
            "point_format": hdr.point_format.id, **points_fingerprint(xyz, np.asarray(las.intensity) / 65535.0)}


def truth_fingerprint(truth) -> dict:
    return {"ids": [t.id for t in truth.targets], "centres_m": [list(map(float, t.centre_socs_m)) for t in truth.targets],
            "points_on_target": [int(t.points_on_target) for t in truth.targets]}


def visit_files(folder: Path, name: str) -> dict:
    c = CONDITIONS[name]
    coarse, _ = simulate_coarse(folder, setup=SETUP, conditions=c, seed=7, coarse_step_deg=0.1)
    plan = plan_from_truth(BridgeScene(BridgeModel(), c, SETUP), min_points=300, rng=np.random.default_rng(3))
    fine, truth = simulate_fine(folder, plan.rois)
    return {"coarse": las_fingerprint(coarse), "fine": las_fingerprint(fine), "fine_truth": truth_fingerprint(truth)}


def fine_epoch_fingerprint(name: str) -> dict:
    cents, _, _, fine = fine_epoch(CONDITIONS[name], SETUP, seed=11, min_points=500)
    return {"ids": sorted(cents), **points_fingerprint(fine.xyz_socs, np.asarray(fine.intensity))}


def observe_fingerprint() -> dict:
    g = sc.BridgeGeometry()
    ids, groups, xyz = g.targets()
    dz = sc.deflection(xyz, groups, ids, g, midspan_m=-0.003, girder_ratio=0.9, asymmetry_m=0.001)
    xyz2 = xyz.copy()
    xyz2[:, 2] += dz
    rng = np.random.default_rng(5)
    st = sc.random_station(g, rng)
    obs, rot = sc.observe(xyz2, ids, scanner_xyz=st, heading_deg=33.0, rng=rng, return_rotation=True)
    return {"xyz_m": [list(map(float, obs[k].xyz)) for k in ids], "cov_m2": [np.asarray(obs[k].cov).tolist()
                                                                             for k in ids],
            "rotation": np.asarray(rot).tolist(), "station_m": list(map(float, st))}


def assert_matches(got, want, path: str = "") -> None:
    """Equal structure and counts; floats within TOL_M (1e-15 m^2 for a covariance) or 1e-9 relative."""
    if isinstance(want, dict):
        assert sorted(got) == sorted(want), f"{path}: keys {sorted(got)} != {sorted(want)}"
        for k in want:
            assert_matches(got[k], want[k], f"{path}.{k}")
    elif isinstance(want, list) and want and isinstance(want[0], str):
        assert got == want, f"{path}: {got} != {want}"
    elif isinstance(want, list):
        assert len(got) == len(want), f"{path}: {len(got)} values, pinned {len(want)}"
        for i, (g, w) in enumerate(zip(got, want, strict=False)):
            assert_matches(g, w, f"{path}[{i}]")
    elif isinstance(want, float):
        tol = max(1e-15 if ".cov_m2" in path else TOL_M, 1e-9 * abs(want))  # covariances are 1e-9-1e-6 m^2
        assert abs(got - want) <= tol, f"{path}: {got!r} != {want!r}"
    else:
        assert got == want, f"{path}: {got!r} != {want!r}"


def pinned() -> dict:
    return json.loads(PINS.read_text())


@pytest.mark.parametrize("name", sorted(CONDITIONS))
def test_visit_files_are_unchanged(tmp_path, name):
    assert_matches(visit_files(tmp_path, name), pinned()[f"visit_{name}"], name)
    las = laspy.read(tmp_path / "coarse.laz")
    assert las.header.point_format.id == 6 and not np.any(las.gps_time)  # no times by default
    scene = json.loads((tmp_path / "scene.json").read_text())
    assert scene["format_version"] == 1 and "model" not in scene


@pytest.mark.parametrize("name", sorted(CONDITIONS))
def test_fine_epoch_points_are_unchanged(name):
    # the simulator's points (the product's centroids of them are tested against the truth elsewhere)
    assert_matches(fine_epoch_fingerprint(name), pinned()[f"epoch_{name}"], name)
    assert fine_epoch(CONDITIONS[name], SETUP, seed=11, min_points=500)[3].time_s is None


def test_centroid_level_observe_is_unchanged():
    assert_matches(observe_fingerprint(), pinned()["observe"], "observe")


def test_a_changed_default_would_be_seen(tmp_path):
    """The fingerprint is not blind: the smallest effects the simulator has, turned on, move it past its tolerance."""
    want = pinned()["visit_plain"]["coarse"]
    for changed in (EpochConditions(midspan_displacement_m=-0.004, range_scale_ppm=1.0),
                    EpochConditions(midspan_displacement_m=-0.0041)):
        coarse, _ = simulate_coarse(tmp_path / str(changed.range_scale_ppm), setup=SETUP, conditions=changed,
                                    seed=7, coarse_step_deg=0.1)
        with pytest.raises(AssertionError):
            assert_matches(las_fingerprint(coarse), want)
    coarse, _ = simulate_coarse(tmp_path / "seed", setup=SETUP, conditions=CONDITIONS["plain"], seed=8,
                                coarse_step_deg=0.1)
    with pytest.raises(AssertionError):  # another random stream
        assert_matches(las_fingerprint(coarse), want)


def _repin() -> None:
    import tempfile

    pins = {}
    for name in sorted(CONDITIONS):
        with tempfile.TemporaryDirectory() as tmp:
            pins[f"visit_{name}"] = visit_files(Path(tmp), name)
        pins[f"epoch_{name}"] = fine_epoch_fingerprint(name)
    pins["observe"] = observe_fingerprint()
    PINS.write_text(json.dumps(pins, indent=1) + "\n")
    print(f"wrote {PINS}")


if __name__ == "__main__":
    _repin() if sys.argv[1:] in ([], ["--repin"]) else sys.exit("usage: python -m tests.lidar.simulate."
                                                                 "test_defaults_pinned")

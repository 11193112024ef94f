"""``info``: header facts without reading points, and the angular steps of regular scans of any size."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidar.io import read_scans, write_scan
from lidar.io.angular_step import PatchSampler, angles_deg, steps_along_lines, steps_from_neighbours
from lidar.io.info import describe_file
from lidar.io.stream import open_stream
from lidar.scan import Scan, normalise_intensity

DATA = Path(__file__).resolve().parents[2] / "data"
# files of other tools that are no scan seen from its origin (foreign-windows/ holds a simulated visit: it is one)
FOREIGN = sorted(p for p in DATA.rglob("*") if p.suffix in (".las", ".laz", ".e57") and p.name not in
                 ("bad-crc.e57", "ZeroPoints.e57") and p.parent.name != "foreign-windows")


def regular_scan(theta_step: float, phi_step: float, n_points: int, *, seed: int = 0, shuffle: bool = False) -> Scan:
    """A line scanner's grid (column by column) over ground and a cylindrical wall 30 m away.

    The window is chosen to hold about ``n_points`` returns; the sky above 20 m gives none and
    3 % of the other returns are missing at random, as on a real scan.
    """
    rng = np.random.default_rng(seed)
    rows = int(np.ceil(min(120.0 / theta_step, np.sqrt(n_points * 1.1 * theta_step / phi_step))))
    cols = int(np.ceil(n_points * 1.1 / rows))
    theta = max(20.0, 88.0 - 0.5 * rows * theta_step) + theta_step * np.arange(rows)
    phi = (350.0 + phi_step * np.arange(cols)) % 360.0  # across the azimuth seam
    pp, tt = np.meshgrid(phi, theta, indexing="ij")
    t, p = np.radians(tt.ravel()), np.radians(pp.ravel())
    d = np.column_stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    r_ground = np.where(d[:, 2] < -1e-3, -1.5 / np.minimum(d[:, 2], -1e-3), np.inf)
    r_wall = 30.0 / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    r = np.minimum(r_ground, r_wall)
    keep = (rng.random(len(r)) > 0.03) & (np.abs(d[:, 2]) * r < 20.0)
    xyz = d[keep] * (r[keep] + rng.normal(0, 0.005, keep.sum()))[:, None]
    xyz = xyz[:n_points]
    if shuffle:
        xyz = xyz[rng.permutation(len(xyz))]
    raw = rng.integers(0, 65535, len(xyz)).astype(np.uint16)
    return Scan(xyz_socs=np.ascontiguousarray(xyz), intensity=normalise_intensity(raw, (0, 65535)), intensity_raw=raw)


@pytest.mark.parametrize("theta_step, phi_step", [(0.009, 0.009), (0.03, 0.03), (0.06, 0.06), (0.2, 0.2),
                                                  (0.01, 0.05), (0.06, 0.02), (0.001, 0.006)])
def test_both_steps_of_regular_scans_from_neighbours_and_from_scan_lines(theta_step, phi_step):
    scan = regular_scan(theta_step, phi_step, 200_000)
    theta, phi = angles_deg(scan.xyz_socs)
    lines = steps_along_lines(theta, phi)
    assert lines.regular
    assert lines.theta_deg == pytest.approx(theta_step, rel=0.01) and lines.phi_deg == pytest.approx(phi_step, rel=0.01)
    order = np.random.default_rng(1).permutation(len(theta))  # file order does not matter to the patches
    sampler = PatchSampler(budget=100_000)
    for k in range(0, len(order), 50_000):
        sampler.add(theta[order[k:k + 50_000]], phi[order[k:k + 50_000]])
    patches = sampler.steps()
    assert patches.regular and patches.points <= 100_000
    assert patches.theta_deg == pytest.approx(theta_step, rel=0.01)
    assert patches.phi_deg == pytest.approx(phi_step, rel=0.01)


def test_a_random_subsample_is_not_taken_for_a_finer_or_coarser_grid():
    scan = regular_scan(0.03, 0.03, 200_000)
    theta, phi = angles_deg(scan.xyz_socs)
    pick = np.random.default_rng(2).choice(len(theta), 20_000, replace=False)
    assert not steps_from_neighbours(theta[pick], phi[pick]).regular  # neighbours several steps apart


@pytest.mark.parametrize("n_points, shuffle", [(200_000, False), (2_000_000, False), (2_000_000, True)])
def test_info_on_large_las_files_within_five_percent(tmp_path, n_points, shuffle):
    path = write_scan(regular_scan(0.009, 0.012, n_points, seed=3, shuffle=shuffle), tmp_path / "big.las")
    quick = describe_file(path)
    (s,) = quick.scans
    assert not quick.stats and s.points == n_points and s.range_m is None  # the header, without the points
    if shuffle:  # consecutive points of a shuffled file are no scan lines: the quick look says so
        assert s.angular_step_deg is None and "--stats" in s.step_from
    else:
        assert s.theta_step_deg == pytest.approx(0.009, rel=0.05) and s.phi_step_deg == pytest.approx(0.012, rel=0.05)
    full = describe_file(path, stats=True)
    (f,) = full.scans
    assert full.stats and f.points == n_points and f.duplicate_points == 0
    assert f.theta_step_deg == pytest.approx(0.009, rel=0.05) and f.phi_step_deg == pytest.approx(0.012, rel=0.05)
    assert f.angular_step_deg == pytest.approx(0.012, rel=0.05)
    assert f.spacing_at_10m_mm == pytest.approx(np.radians(0.012) * 1e4, rel=0.05)


def test_the_demo_coarse_scan_is_0_06_degrees(tmp_path):
    from lidar.simulate import EpochConditions, ScannerSetup
    from lidar.simulate.files import simulate_coarse

    path, _ = simulate_coarse(tmp_path, setup=ScannerSetup((18.0, -13.0, 1.5), heading_deg=75.0),
                              conditions=EpochConditions(), seed=77, coarse_step_deg=0.06)
    for stats in (False, True):
        (s,) = describe_file(path, stats=stats).scans
        assert s.theta_step_deg == pytest.approx(0.06, rel=0.01) and s.phi_step_deg == pytest.approx(0.06, rel=0.01)


@pytest.mark.parametrize("path", FOREIGN, ids=lambda p: p.name)
def test_foreign_files_get_no_invented_step(path):
    """Airborne LAS in a project frame, a bunny, a cube: no regular scan seen from the origin, so no step."""
    for stats in (False, True):
        info = describe_file(path, stats=stats)
        for s in info.scans:
            assert s.angular_step_deg is None
            if stats:
                assert any("project frame" in p or "regular angular grid" in p for p in s.problems), s.problems


@pytest.mark.parametrize("path", FOREIGN, ids=lambda p: p.name)
def test_header_facts_match_the_points(path):
    quick, full, scans = describe_file(path), describe_file(path, stats=True), read_scans(path)
    assert [s.points for s in full.scans] == [len(s) for s in scans]
    for q, f, scan in zip(quick.scans, full.scans, scans, strict=False):
        np.testing.assert_allclose(f.bounds_min, scan.xyz_socs.min(axis=0))
        np.testing.assert_allclose(f.bounds_max, scan.xyz_socs.max(axis=0))
        if q.bounds_min is not None:  # the header's bounds, where it has them
            np.testing.assert_allclose(q.bounds_min, scan.xyz_socs.min(axis=0), atol=0.01)
        assert (f.intensity_raw_range is None) == (scan.intensity_raw is None)
        if scan.intensity_raw is not None:
            assert f.intensity_raw_range == (float(scan.intensity_raw.min()), float(scan.intensity_raw.max()))
            assert f.intensity_convention == scan.metadata["intensity_convention"]
        assert (q.pose is None) == (scan.pose is None)


@pytest.mark.parametrize("suffix", [".las", ".laz", ".e57", ".ply", ".pcd", ".ptx", ".xyz"])
def test_streamed_chunks_are_the_points(tmp_path, suffix):
    scan = regular_scan(0.05, 0.05, 30_000, seed=5)
    path = write_scan(scan, tmp_path / f"s{suffix}")
    (ref,) = read_scans(path)
    stream = open_stream(path)
    chunks = list(stream.chunks(0, chunk_points=7_000))
    assert stream.streamed == (suffix in (".las", ".laz", ".e57", ".ply", ".pcd"))
    np.testing.assert_array_equal(np.vstack([c.xyz for c in chunks]), ref.xyz_socs)
    np.testing.assert_array_equal(np.concatenate([c.raw for c in chunks]), ref.intensity_raw)
    assert max(len(c.xyz) for c in chunks) <= 7_000 or not stream.streamed

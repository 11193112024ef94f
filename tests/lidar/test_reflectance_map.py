import numpy as np
import pytest

from common.errors import InputError
from lidar.angles import direction_from_angles
from lidar.detection import detect_reflectors
from lidar.reflectance_map import estimate_step_deg, reflectance_map


def grid_scan(theta_range, phi_range, step, bright=()):
    t = np.arange(*theta_range, step)
    p = np.arange(*phi_range, step)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    tt, pp = tt.ravel(), np.mod(pp.ravel(), 360.0)
    xyz = direction_from_angles(tt, pp) * 20.0
    inten = np.full(len(tt), 0.2, np.float32)
    for (tc, pc, r_deg) in bright:
        d = np.hypot(tt - tc, (np.mod(pp - pc + 180, 360) - 180) * np.sin(np.radians(tc)))
        inten[d <= r_deg] = 0.95
    return xyz, inten


def test_cells_hold_max_mean_range_and_count():
    xyz, inten = grid_scan((80, 90), (10, 20), 0.05, bright=[(85, 15, 0.07)])
    m = reflectance_map(xyz, inten, step_deg=0.1)
    assert m.count.sum() == len(xyz)
    assert np.nanmax(m.max_intensity) == pytest.approx(0.95)
    assert np.nanmin(m.mean_intensity) == pytest.approx(0.2)
    np.testing.assert_allclose(m.range_m[m.count > 0], 20.0, rtol=1e-6)


def test_step_is_estimated_from_density():
    xyz, inten = grid_scan((60, 100), (0, 40), 0.05)
    from lidar.angles import spherical_from_xyz

    t, p, _ = spherical_from_xyz(xyz)
    assert estimate_step_deg(t, p) == pytest.approx(0.05, rel=0.15)


def test_target_on_the_azimuth_seam_is_one_blob():
    xyz, inten = grid_scan((80, 95), (-20, 20), 0.02, bright=[(88.0, 0.0, 0.08)])
    m = reflectance_map(xyz, inten)
    assert m.phi0_deg < 0 < m.phi0_deg + m.shape[1] * m.step_deg
    det = detect_reflectors(m, target_diameter_m=0.056, threshold=0.6)
    assert len(det.detections) == 1
    d = det.detections[0]
    assert abs((d.phi_deg + 180) % 360 - 180) < 0.5 * m.step_deg and d.theta_deg == pytest.approx(88.0, abs=0.5 * m.step_deg)


def test_full_circle_scan_merges_blobs_across_the_seam():
    xyz, inten = grid_scan((85, 95), (0, 360), 0.05, bright=[(90.0, 0.0, 0.12)])
    m = reflectance_map(xyz, inten, step_deg=0.05)
    assert m.full_circle
    det = detect_reflectors(m, target_diameter_m=0.08, threshold=0.6)
    assert len(det.detections) == 1
    assert abs((det.detections[0].phi_deg + 180) % 360 - 180) < 0.02


def test_a_blob_of_the_first_column_joins_every_blob_of_the_last_it_touches_and_only_it_moves():
    from lidar.detection import _merge_across_seam

    first = np.array([0, 1, 1, 1, 0, 0, 2])  # labels down the first column: blobs 1 and 2
    last = np.array([0, 5, 0, 6, 0, 0, 0])  # down the last column: blobs 5 and 6, both beside blob 1
    roots, shift = _merge_across_seam(first, last, 6, 10)
    assert roots.tolist() == [0, 6, 2, 3, 4, 6, 6]  # one blob, named by its largest label
    assert shift.tolist() == [0, 10, 0, 0, 0, 0, 0]  # blob 1 continues after the last column; 5 and 6 stay


def test_large_bright_patch_is_rejected_not_detected():
    xyz, inten = grid_scan((80, 95), (0, 30), 0.02, bright=[(85, 10, 0.07), (88, 20, 1.5)])
    det = detect_reflectors(reflectance_map(xyz, inten), target_diameter_m=0.05, threshold=0.6)
    assert len(det.detections) == 1 and len(det.rejected) == 1
    assert det.detections[0].phi_deg == pytest.approx(10, abs=0.02)


def test_bad_input():
    with pytest.raises(InputError):
        reflectance_map(np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(InputError):
        reflectance_map(np.ones((3, 3)), np.zeros(2))
    with pytest.raises(InputError):
        reflectance_map(np.ones((3, 3)), np.zeros(3), step_deg=float("nan"))


def test_reduce_map_keeps_small_bright_targets_and_geometry():
    from lidar.reflectance_map import ReflectanceMap, reduce_map

    h, w = 300, 1000
    mx = np.full((h, w), 0.1, np.float32)
    mx[:20] = np.nan  # sky
    mx[151, 733] = 0.95  # one bright cell: a distant target
    cnt = np.where(np.isnan(mx), 0, 2).astype(np.int32)
    rng = np.where(cnt > 0, 20.0, np.nan).astype(np.float32)
    rmap = ReflectanceMap(80.0, -10.0, 0.05, mx, np.where(cnt > 0, mx, np.nan), rng, cnt, False, int(cnt.sum()))
    red = reduce_map(rmap, max_cells=20_000)
    assert red.count.size <= 20_000 and red.count.sum() == cnt.sum()
    k = round(red.step_deg / rmap.step_deg)
    assert k > 1 and red.theta0_deg == 80.0 and red.phi0_deg == -10.0
    assert np.nanmax(red.max_intensity) == np.float32(0.95)
    r, c = np.unravel_index(np.nanargmax(red.max_intensity), red.shape)
    t, p = red.cell_angles(r, c)
    t0, p0 = rmap.cell_angles(151, 733)
    assert abs(t - t0) <= red.step_deg and abs(p - p0) <= red.step_deg
    assert np.isnan(red.max_intensity[0, 0]) and np.allclose(red.range_m[-1, :-1], 20.0)
    assert reduce_map(rmap, max_cells=10 ** 7) is rmap


@pytest.mark.parametrize("suffix", [".las", ".laz", ".ply"])
def test_the_map_of_a_file_is_the_map_of_its_scan(tmp_path, suffix):
    """Binned straight from the LAS records (one fused pass) or read whole first: the same map."""
    from lidar.io import read_scan, write_scan
    from lidar.reflectance_map import reflectance_map_from_file
    from lidar.scan import Scan, normalise_intensity

    xyz, inten = grid_scan((60, 100), (350, 380), 0.04, bright=[(85, 5, 0.1)])
    raw = np.round(inten * 40000 + 1000).astype(np.uint16)
    scan = Scan(xyz_socs=xyz * np.linspace(0.5, 2.0, len(xyz))[:, None], intensity=normalise_intensity(raw),
                intensity_raw=raw)
    path = write_scan(scan, tmp_path / f"s{suffix}")
    back = read_scan(path)
    a = reflectance_map(back.xyz_socs, back.intensity)
    b = reflectance_map_from_file(path)
    assert (a.theta0_deg, a.phi0_deg, a.step_deg, a.shape, a.full_circle) == \
        (b.theta0_deg, b.phi0_deg, b.step_deg, b.shape, b.full_circle)
    np.testing.assert_array_equal(a.count, b.count)
    for name in ("max_intensity", "mean_intensity", "range_m"):
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), atol=1e-5, equal_nan=True)

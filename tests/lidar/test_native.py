"""The coarse map (lidar/native's compiled loops): each cell what plain arithmetic on its points gives; never
stale (issue 27; issue 43: one implementation of the pass, no numpy twin)."""
from __future__ import annotations

import mmap
import shutil
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidar.native as native
from common.errors import ScanFormatError, SurveyError
from lidar.reflectance_map import reflectance_map, reflectance_map_from_file

FIELDS = ("count", "max_intensity", "mean_intensity", "range_m")


def _las(path: Path, n: int, *, point_format: int, scale: float, full_circle: bool, seed: int) -> Path:
    """Points at random directions and ranges, with the awkward ones: the origin, the zenith, signed zeros."""
    rng = np.random.default_rng(seed)
    az = rng.uniform(0, 360, n) if full_circle else rng.uniform(100, 240, n)
    ze = rng.uniform(20, 160, n)
    r = rng.uniform(0.5, 90, n)
    t, p = np.radians(ze), np.radians(az)
    xyz = np.c_[r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)]
    xyz[:20] = 0.0
    xyz[20:40, :2] = 0.0
    xyz[40:60, 1] = -0.0
    xyz[60:80, 0] = -rng.uniform(0, 1e-3, 20)
    header = laspy.LasHeader(point_format=point_format, version="1.4")
    header.scales, header.offsets = [scale] * 3, [0.25, -3.5, 1.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    las.intensity = rng.integers(0, 65535, n).astype(np.uint16)
    las.write(path)
    return path


def _assert_same_bits(a, b) -> None:
    assert (a.theta0_deg, a.phi0_deg, a.step_deg, a.shape, a.full_circle, a.n_points) == \
        (b.theta0_deg, b.phi0_deg, b.step_deg, b.shape, b.full_circle, b.n_points)
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name


STEP = 0.1


def _cell_scan(seed: int, cells: int, *, full_circle: bool):
    """Points near the centres of ``cells`` cells of a 0.1-degree grid (1 to 5 a cell), far from every cell edge.

    The reference map is then plain arithmetic on each cell's points, with no doubt which cell a point is in.
    """
    rng = np.random.default_rng(seed)
    rows = rng.integers(200, 1500, cells)  # zenith 20-150 deg
    cols = rng.integers(0, 3600, cells) if full_circle else rng.integers(1000, 2400, cells)
    keys = np.unique(np.c_[rows, cols], axis=0)
    per = rng.integers(1, 6, len(keys))
    cell = np.repeat(keys, per, axis=0)
    n = len(cell)
    theta = (cell[:, 0] + 0.5 + rng.uniform(-0.2, 0.2, n)) * STEP
    phi = (cell[:, 1] + 0.5 + rng.uniform(-0.2, 0.2, n)) * STEP
    r = rng.uniform(5.0, 60.0, n)
    t, p = np.radians(theta), np.radians(phi)
    xyz = np.c_[r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t)]
    intensity = rng.integers(0, 65535, n).astype(np.uint16)
    order = rng.permutation(n)  # the points of a cell are not neighbours in the file
    return xyz[order], intensity[order], cell[order]


def _reference(cell: np.ndarray, xyz: np.ndarray, intensity01: np.ndarray) -> dict:
    """Each cell's count, largest and mean intensity and mean range, by plain arithmetic on its points."""
    r = np.linalg.norm(xyz, axis=1)
    keys, inverse = np.unique(cell, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    out = {}
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(keys) + 1))
    for k, key in enumerate(keys):
        mine = order[bounds[k]:bounds[k + 1]]
        out[tuple(key)] = (len(mine), float(intensity01[mine].max()), float(intensity01[mine].mean()),
                           float(r[mine].mean()))
    return out


def _assert_map_is(rmap, reference: dict, n: int) -> None:
    assert rmap.step_deg == STEP and rmap.n_points == n and int(rmap.count.sum()) == n
    keys = np.array(list(reference))
    row, col = (np.rint(x).astype(int) for x in rmap.cells_of((keys[:, 0] + 0.5) * STEP, (keys[:, 1] + 0.5) * STEP))
    want = np.array(list(reference.values()))
    assert np.array_equal(rmap.count[row, col], want[:, 0].astype(np.int32))
    np.testing.assert_allclose(rmap.max_intensity[row, col], want[:, 1], rtol=0, atol=1e-6)
    np.testing.assert_allclose(rmap.mean_intensity[row, col], want[:, 2], rtol=0, atol=1e-5)
    np.testing.assert_allclose(rmap.range_m[row, col], want[:, 3], rtol=1e-5)
    empty = rmap.count == 0
    assert empty.sum() == rmap.count.size - len(reference) and np.isnan(rmap.max_intensity[empty]).all()


@pytest.mark.parametrize("cells, full_circle, point_format", [
    (2_000, False, 0),  # 20-byte records, fewer points than a block
    (120_000, True, 3),  # 34-byte records (most integers unaligned), several chunks, the last one short
    (90_000, False, 6),  # 30-byte records, as the bench's big scan
])
def test_the_map_of_a_las_file_is_the_plain_binning_of_its_points(tmp_path, cells, full_circle, point_format):
    """plan-file's and detect's path: the records binned and the cells finished by the compiled loops."""
    xyz, intensity, cell = _cell_scan(cells, cells, full_circle=full_circle)
    header = laspy.LasHeader(point_format=point_format, version="1.4")
    header.scales, header.offsets = [1e-4] * 3, [0.25, -3.5, 1.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    las.intensity = intensity
    las.write(tmp_path / "s.las")
    back = laspy.read(tmp_path / "s.las")  # the coordinates as stored (scaled integers)
    stored = np.c_[back.x, back.y, back.z]
    lo, hi = float(intensity.min()), float(intensity.max())
    intensity01 = (intensity.astype(np.float64) - lo) / (hi - lo)
    rmap = reflectance_map_from_file(tmp_path / "s.las", step_deg=STEP)
    _assert_map_is(rmap, _reference(cell, stored, intensity01), len(xyz))
    assert rmap.full_circle == full_circle


def test_the_map_of_points_in_memory_is_the_plain_binning_of_them():
    """The campaign's path (add-epoch, plan, process): a scan held in memory, the same compiled merge and finish."""
    xyz, intensity, cell = _cell_scan(7, 50_000, full_circle=False)
    intensity01 = intensity / 65535.0
    rmap = reflectance_map(xyz, intensity01, step_deg=STEP)
    _assert_map_is(rmap, _reference(cell, xyz, intensity01), len(xyz))


def test_a_strided_survey_of_a_large_scan_finds_its_extent(tmp_path):
    """Above two million points the survey samples every k-th record; the map still holds every point."""
    path = _las(tmp_path / "s.las", 2_400_001, point_format=1, scale=1e-3, full_circle=False, seed=3)
    rmap = reflectance_map_from_file(path)
    assert rmap.n_points == int(rmap.count.sum()) == 2_400_001 and not rmap.full_circle
    assert rmap.count[0].any() and rmap.count[-1].any()  # the extent was trimmed to the points, not cut


def test_the_library_is_built():
    native.coarse_map_library.cache_clear()
    assert native.coarse_map_library() is not None


def test_a_missing_or_stale_library_is_one_clear_error(tmp_path, monkeypatch):
    monkeypatch.setattr(native, "_HERE", tmp_path)
    native.coarse_map_library.cache_clear()
    try:
        with pytest.raises(SurveyError, match=r"not built here.*\./run setup"):
            native.coarse_map_library()
    finally:
        native.coarse_map_library.cache_clear()


def test_a_library_built_from_another_source_is_left_unused(tmp_path):
    built = [p for p in Path(native.__file__).parent.glob("_coarse_map*") if p.suffix in (".so", ".pyd")]
    assert built and native.load_coarse_map(Path(native.__file__).parent) is not None
    shutil.copy(built[0], tmp_path / built[0].name)
    source = (Path(native.__file__).parent / "coarse_map.c").read_text()
    (tmp_path / "coarse_map.c").write_text(source)
    assert native.load_coarse_map(tmp_path) is not None
    (tmp_path / "coarse_map.c").write_text(source.replace("BLOCK 256", "BLOCK 512"))
    assert native.load_coarse_map(tmp_path) is None
    assert native.load_coarse_map(tmp_path / "nowhere") is None


def test_a_file_system_that_cannot_map_files_gives_the_same_map(tmp_path, monkeypatch):
    path = _las(tmp_path / "s.las", 200_000, point_format=6, scale=1e-4, full_circle=False, seed=5)
    mapped = reflectance_map_from_file(path)

    anonymous = mmap.mmap

    def refuse(fileno, *args, **kwargs):  # files only: the map's cells still come from anonymous memory
        if fileno != -1:
            raise OSError(19, "No such device")
        return anonymous(fileno, *args, **kwargs)

    monkeypatch.setattr(mmap, "mmap", refuse)
    _assert_same_bits(reflectance_map_from_file(path), mapped)


def test_a_file_shortened_after_its_header_was_read_is_one_error(tmp_path, monkeypatch):
    import lidar.io.las as las

    path = _las(tmp_path / "s.las", 100_000, point_format=6, scale=1e-4, full_circle=False, seed=6)
    check = las.check_las_header

    def check_then_shorten(p):  # another program cuts the file between the header check and the reading
        facts = check(p)
        with open(p, "r+b") as fh:
            fh.truncate(facts.offset_to_points + 1000 * facts.record_length)
        return facts

    monkeypatch.setattr(las, "check_las_header", check_then_shorten)
    with pytest.raises(ScanFormatError, match="truncated"):
        reflectance_map_from_file(path)

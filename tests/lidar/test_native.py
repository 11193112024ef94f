"""The compiled coarse map (lidar/native) gives numpy's maps to the bit, and is never used stale (issue 27)."""
from __future__ import annotations

import mmap
import os
import shutil
from pathlib import Path

import laspy
import numpy as np
import pytest

import lidar.native as native
from common.errors import ScanFormatError
from lidar.reflectance_map import reflectance_map_from_file

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


def _map(path: Path, monkeypatch, compiled: bool):
    monkeypatch.setenv("BRIDGESURVEY_NATIVE", "1" if compiled else "0")
    native.coarse_map_library.cache_clear()
    try:
        if compiled and native.coarse_map_library() is None:
            pytest.skip("the compiled coarse map is not built here")
        return reflectance_map_from_file(path)
    finally:
        native.coarse_map_library.cache_clear()


def _assert_same_bits(a, b) -> None:
    assert (a.theta0_deg, a.phi0_deg, a.step_deg, a.shape, a.full_circle, a.n_points) == \
        (b.theta0_deg, b.phi0_deg, b.step_deg, b.shape, b.full_circle, b.n_points)
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name


@pytest.mark.parametrize("n, point_format, scale, full_circle", [
    (3_001, 0, 1e-3, False),  # 20-byte records, fewer points than a block
    (300_017, 3, 1e-4, True),  # 34-byte records: most integers unaligned; two chunks, the last one short
    (600_000, 6, 2.5e-4, False),  # 30-byte records, as the bench's big scan
    (550_123, 7, 1e-5, True),  # 36-byte records, a fine scale
])
def test_the_compiled_map_is_numpys_to_the_bit(tmp_path, monkeypatch, n, point_format, scale, full_circle):
    path = _las(tmp_path / "s.las", n, point_format=point_format, scale=scale, full_circle=full_circle, seed=n)
    _assert_same_bits(_map(path, monkeypatch, True), _map(path, monkeypatch, False))


def test_a_strided_survey_of_a_large_scan_is_numpys_to_the_bit(tmp_path, monkeypatch):
    """Above two million points the survey samples every k-th record; both paths take the same ones."""
    path = _las(tmp_path / "s.las", 4_200_001, point_format=1, scale=1e-3, full_circle=False, seed=3)
    _assert_same_bits(_map(path, monkeypatch, True), _map(path, monkeypatch, False))


def test_the_library_is_built_where_there_is_a_compiler():
    if shutil.which("cc") is None and shutil.which("gcc") is None:
        pytest.skip("no C compiler: numpy does the work")
    if os.environ.get("BRIDGESURVEY_NATIVE") == "0":
        pytest.skip("switched off")
    native.coarse_map_library.cache_clear()
    assert native.coarse_map_library() is not None, "lidar/native/_coarse_map was not built (./run setup builds it)"


def test_a_library_built_from_another_source_is_left_unused(tmp_path):
    built = [p for p in Path(native.__file__).parent.glob("_coarse_map*") if p.suffix in (".so", ".pyd")]
    if not built or native.load_coarse_map(Path(native.__file__).parent) is None:
        pytest.skip("the compiled coarse map is not built here")
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

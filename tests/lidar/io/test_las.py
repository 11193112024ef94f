
import laspy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from common.errors import ScanFormatError
from lidar.io import read_scan, read_scans, write_scan
from lidar.io.las import read_las
from lidar.scan import Scan, normalise_intensity


@pytest.mark.parametrize("name", ["simple.las", "simple.laz", "simple1_4.las", "test1_4.las", "extrabytes.las"])
def test_reads_files_written_by_other_tools_like_laspy(data_dir, name):
    path = data_dir / "las" / name
    ours = read_scan(path)
    ref = laspy.read(path)
    np.testing.assert_array_equal(ours.xyz_socs[:, 0], np.asarray(ref.x))
    np.testing.assert_array_equal(ours.xyz_socs[:, 2], np.asarray(ref.z))
    np.testing.assert_array_equal(ours.intensity_raw, np.asarray(ref.intensity))
    assert ours.intensity.dtype == np.float32
    assert 0.0 <= ours.intensity.min() <= ours.intensity.max() <= 1.0
    assert ours.metadata["point_format"] == ref.header.point_format.id


def test_chunked_reading_gives_the_same_points(data_dir):
    whole = read_las(data_dir / "las" / "simple.laz")
    chunked = read_las(data_dir / "las" / "simple.laz", chunk_points=100)
    np.testing.assert_array_equal(whole.xyz_socs, chunked.xyz_socs)
    chunked_las = read_las(data_dir / "las" / "simple.las", chunk_points=77)
    np.testing.assert_array_equal(whole.xyz_socs, chunked_las.xyz_socs)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_round_trip_keeps_tenth_of_millimetre_and_pose(tmp_path, small_scan, suffix):
    path = write_scan(small_scan, tmp_path / f"scan{suffix}")
    back = read_scan(path)
    assert np.max(np.abs(back.xyz_socs - small_scan.xyz_socs)) < 1e-5
    np.testing.assert_array_equal(back.intensity_raw, small_scan.intensity_raw)
    np.testing.assert_allclose(back.pose, small_scan.pose)
    assert not list(tmp_path.glob(".*part*")), "temporary file left behind"
    assert (path.read_bytes()[:4] == b"LASF") and (back.metadata["compressed"] == (suffix == ".laz"))


@settings(max_examples=25, deadline=None)
@given(xyz=arrays(np.float64, st.tuples(st.integers(1, 50), st.just(3)),
                  elements=st.floats(-2000, 2000, allow_nan=False)))
def test_round_trip_any_coordinates(tmp_path_factory, xyz):
    path = tmp_path_factory.mktemp("rt") / "p.las"
    scan = Scan(xyz_socs=xyz, intensity=np.zeros(len(xyz), np.float32))
    back = read_scan(write_scan(scan, path))
    assert np.max(np.abs(back.xyz_socs - xyz)) <= 1e-5


def test_truncated_las_is_refused_naming_the_file(tmp_path, data_dir):
    blob = (data_dir / "las" / "simple.las").read_bytes()
    bad = tmp_path / "cut.las"
    bad.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(ScanFormatError, match=r"cut\.las: truncated"):
        read_scan(bad)


def test_truncated_laz_is_refused(tmp_path, data_dir):
    blob = (data_dir / "las" / "simple.laz").read_bytes()
    bad = tmp_path / "cut.laz"
    bad.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(ScanFormatError, match=r"cut\.laz"):
        read_scan(bad)


def test_garbage_with_las_suffix_is_refused(tmp_path):
    bad = tmp_path / "noise.las"
    bad.write_bytes(b"\x00\x01garbage" * 50)
    with pytest.raises(ScanFormatError, match="does not start like a LAS file"):
        read_scan(bad)


def test_corrupt_header_is_refused(tmp_path, data_dir):
    blob = bytearray((data_dir / "las" / "simple.las").read_bytes())
    blob[104] = 42  # point data format 42 does not exist
    bad = tmp_path / "badformat.las"
    bad.write_bytes(bytes(blob))
    with pytest.raises(ScanFormatError, match="badformat.las"):
        read_scan(bad)


def test_zero_point_las_is_refused(tmp_path):
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    path = tmp_path / "empty.las"
    las.write(path)
    with pytest.raises(ScanFormatError, match="0 points"):
        read_scans(path)


def test_empty_and_missing_files(tmp_path):
    (tmp_path / "zero.las").write_bytes(b"")
    with pytest.raises(ScanFormatError, match="empty"):
        read_scan(tmp_path / "zero.las")
    with pytest.raises(ScanFormatError, match="no such file"):
        read_scan(tmp_path / "absent.laz")


def test_constant_intensity_normalises_to_zero():
    assert normalise_intensity(np.full(5, 7, np.uint16)).tolist() == [0.0] * 5

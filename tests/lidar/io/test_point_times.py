"""Point times (``Scan.time_s``): LAS ``gps_time`` and E57 ``timeStamp`` in and out."""
import pickle
from pathlib import Path

import laspy
import numpy as np
import pytest

from common.errors import InputError
from lidar.io.e57 import read_e57, write_e57
from lidar.io.las import read_las, write_las
from lidar.scan import Scan, normalise_intensity

FOREIGN = Path("/work/shared/data/foreign-windows/fine.laz")


def timed_scan(n: int = 2000, *, t0: float = 345_600.123456, pose=None) -> Scan:
    rng = np.random.default_rng(3)
    xyz = rng.normal(0.0, 20.0, (n, 3))
    raw = rng.integers(0, 65535, n).astype(np.uint16)
    return Scan(xyz, normalise_intensity(raw, (0, 65535)), raw, pose=pose, name="timed",
                time_s=t0 + np.arange(n) / 122_000.0)


def test_scan_keeps_times_through_subset_concatenate_and_pickle():
    s = timed_scan(100)
    sub = s.subset(np.arange(10, 20))
    np.testing.assert_array_equal(sub.time_s, s.time_s[10:20])
    both = Scan.concatenate([s, sub])
    np.testing.assert_array_equal(both.time_s, np.concatenate([s.time_s, sub.time_s]))
    untimed = Scan(s.xyz_socs, s.intensity, s.intensity_raw)
    assert Scan.concatenate([s, untimed]).time_s is None
    back = pickle.loads(pickle.dumps(s))
    np.testing.assert_array_equal(back.time_s, s.time_s)
    assert back.time_s.dtype == np.float64
    with pytest.raises(InputError, match="time_s"):
        Scan(s.xyz_socs, time_s=np.zeros(3))


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_round_trip_keeps_times_exactly(tmp_path, suffix):
    s = timed_scan()
    back = read_las(write_las(s, tmp_path / f"t{suffix}"))
    assert back.metadata["has_time"] is True
    np.testing.assert_array_equal(back.time_s, s.time_s)


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_scan_without_times_writes_zero_gps_time_and_reads_without_times(tmp_path, suffix):
    s = timed_scan()
    plain = Scan(s.xyz_socs, s.intensity, s.intensity_raw)
    p = write_las(plain, tmp_path / f"p{suffix}")
    las = laspy.read(p)
    assert las.header.point_format.id == 6 and not np.any(las.gps_time)
    back = read_las(p)
    assert back.time_s is None and back.metadata["has_time"] is False


@pytest.mark.parametrize("fmt", [0, 1, 3, 6, 8])
def test_reads_gps_time_of_a_file_written_by_laspy(tmp_path, fmt):
    n = 500
    header = laspy.LasHeader(point_format=fmt, version="1.4" if fmt >= 6 else "1.2")
    header.scales = np.array([1e-4] * 3)
    las = laspy.LasData(header)
    las.x = np.linspace(0, 10, n)
    las.y = np.zeros(n)
    las.z = np.ones(n)
    las.intensity = np.arange(n, dtype=np.uint16)
    times = 1000.0 + np.arange(n) * 2e-5
    if fmt != 0:
        las.gps_time = times
    p = tmp_path / f"f{fmt}.las"
    las.write(p)
    back = read_las(p)
    if fmt == 0:
        assert back.time_s is None and back.metadata["has_time"] is False
    else:
        assert back.metadata["has_time"] is True
        np.testing.assert_array_equal(back.time_s, times)


def test_e57_round_trip_keeps_times_and_poses(tmp_path):
    pose = np.eye(4)
    pose[:3, 3] = (2_500_000.0, 5_600_000.0, 40.0)
    s = timed_scan(pose=pose)
    plain = Scan(s.xyz_socs[:50], s.intensity[:50], s.intensity_raw[:50], name="plain")
    a, b = read_e57(write_e57([s, plain], tmp_path / "t.e57"))
    assert a.metadata["has_time"] is True and b.metadata["has_time"] is False
    np.testing.assert_array_equal(a.time_s, s.time_s)
    assert b.time_s is None
    np.testing.assert_allclose(a.pose, pose)
    assert np.max(np.abs(a.xyz_socs - s.xyz_socs)) < 1e-4  # single-precision coordinates, as pye57 writes
    np.testing.assert_array_equal(a.intensity_raw, s.intensity_raw.astype(a.intensity_raw.dtype))


@pytest.mark.skipif(not FOREIGN.is_file(), reason="the foreign sample is not on this machine")
def test_foreign_sample_reads_with_times_and_thirty_second_gaps():
    s = read_las(FOREIGN)
    assert s.metadata["point_format"] == 1 and s.metadata["has_time"] is True
    d = np.diff(s.time_s)
    assert np.all(d >= 0)
    gaps = d[d > 5.0]
    assert gaps.size == 9  # ten windows
    np.testing.assert_allclose(gaps, 30.0, atol=0.01)


def test_e57_time_stamps_flagged_invalid_read_as_nan(tmp_path):
    import uuid

    import pye57
    from pye57 import libe57

    path = str(tmp_path / "inv.e57")
    e = pye57.E57(path, mode="w")
    imf = e.image_file
    node = libe57.StructureNode(imf)
    node.set("guid", libe57.StringNode(imf, f"{{{uuid.uuid4()}}}"))
    proto = libe57.StructureNode(imf)
    for f in ("cartesianX", "cartesianY", "cartesianZ"):
        proto.set(f, libe57.FloatNode(imf, 0.0, libe57.E57_DOUBLE, -100.0, 100.0))
    proto.set("timeStamp", libe57.FloatNode(imf, 0.0, libe57.E57_SINGLE, 0.0, 1000.0))  # single, as some tools
    proto.set("isTimeStampInvalid", libe57.IntegerNode(imf, 0, 0, 1))
    points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
    node.set("points", points)
    e.data3d.append(node)
    n = 100
    arrays = {"cartesianX": np.linspace(1, 2, n), "cartesianY": np.ones(n), "cartesianZ": np.ones(n),
              "timeStamp": np.arange(n) * 0.5, "isTimeStampInvalid": (np.arange(n) % 10 == 0).astype(np.int8)}
    buffers = libe57.VectorSourceDestBuffer()
    for k, a in arrays.items():
        buffers.append(libe57.SourceDestBuffer(imf, k, a, n, True, True))
    w = points.writer(buffers)
    w.write(n)
    w.close()
    e.close()
    (scan,) = read_e57(path)
    assert scan.metadata["has_time"] is True
    assert np.isnan(scan.time_s[::10]).all()
    np.testing.assert_array_equal(scan.time_s[1:10], np.arange(1, 10) * 0.5)

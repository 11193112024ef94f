"""Chunked conversion gives what the whole-scan writers give, and LAS to LAZ copies every record."""
from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest

from common.errors import InputError
from lidar.io import read_scans, write_scan
from lidar.io.convert import convert_file
from tests.lidar.io.fuzz_cases import sample_scan

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.mark.parametrize("src_suffix", [".las", ".laz", ".e57", ".ply", ".pcd"])
@pytest.mark.parametrize("dst_suffix", [".las", ".laz", ".ply", ".pcd", ".xyz", ".pts"])
def test_chunked_conversion_equals_the_whole_scan_writer(tmp_path, src_suffix, dst_suffix):
    scan = sample_scan()
    src = write_scan(scan, tmp_path / f"src{src_suffix}")
    (whole_in,) = read_scans(src)
    done = convert_file(src, tmp_path / f"out{dst_suffix}", chunk_points=97)
    assert done.streamed and done.points == len(whole_in)
    (back,) = read_scans(done.path)
    (ref,) = read_scans(write_scan(whole_in, tmp_path / f"ref{dst_suffix}"))
    np.testing.assert_allclose(back.xyz_socs, ref.xyz_socs, atol=1e-9)
    np.testing.assert_array_equal(back.intensity_raw, ref.intensity_raw)
    assert (back.pose is None) == (ref.pose is None)
    if ref.pose is not None:
        np.testing.assert_allclose(back.pose, ref.pose, atol=1e-9)


def test_las_to_laz_copies_every_record_and_dimension(tmp_path):
    src = DATA / "las" / "extrabytes.las"
    done = convert_file(src, tmp_path / "x.laz", chunk_points=100)
    assert done.lossless_copy and done.points == 1065
    a, b = laspy.read(src), laspy.read(done.path)
    assert list(a.point_format.dimension_names) == list(b.point_format.dimension_names)
    for name in a.point_format.dimension_names:
        np.testing.assert_array_equal(np.asarray(a[name]), np.asarray(b[name]))


def test_multi_scan_inputs_need_e57_or_a_choice(tmp_path):
    scans = [sample_scan(), sample_scan()]
    from lidar.io.e57 import write_e57

    src = write_e57(scans, tmp_path / "two.e57")
    with pytest.raises(InputError, match="convert to .e57"):
        convert_file(src, tmp_path / "a.las")
    with pytest.raises(InputError, match="--scan must be 0-1"):
        convert_file(src, tmp_path / "a.las", scan=2)
    done = convert_file(src, tmp_path / "b.las", scan=1)
    assert done.points == len(scans[1])
    both = convert_file(src, tmp_path / "c.e57")
    assert both.scans == 2 and not both.streamed

"""The time a scan file records of itself: the default date of a new epoch."""
import datetime as dt
from pathlib import Path

import numpy as np

from lidar.io.scan_time import gps_to_utc, scan_file_time

DATA = Path(__file__).resolve().parents[2] / "data"


def test_the_points_gps_time_comes_before_the_header_day():
    t = scan_file_time(DATA / "las" / "test1_4.las")  # adjusted standard GPS time in its points
    assert t is not None and not t.day_only and t.source == "the GPS time of its first point"
    assert t.when.tzinfo is not None and t.when.year == 2014


def test_a_header_creation_day_is_the_day_only():
    t = scan_file_time(DATA / "las" / "simple1_4.las")  # GPS week time: no date in the points
    assert t is not None and t.day_only and t.when == dt.datetime(2012, 1, 13, tzinfo=dt.UTC)


def test_no_time_a_placeholder_or_a_damaged_file_give_none(tmp_path):
    assert scan_file_time(DATA / "las" / "simple.las") is None          # no creation day, week times
    assert scan_file_time(DATA / "e57" / "ColourRepresentation.e57") is None  # acquisitionStart 0: 1980
    assert scan_file_time(DATA / "e57" / "bunnyDouble.e57") is None      # no acquisitionStart at all
    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"LASF" + b"\0" * 40)
    assert scan_file_time(bad) is None
    xyz = tmp_path / "scan.xyz"
    np.savetxt(xyz, np.ones((5, 3)))
    assert scan_file_time(xyz) is None and scan_file_time(tmp_path / "missing.laz") is None


def test_gps_time_has_its_leap_seconds():
    assert gps_to_utc(0) == dt.datetime(1980, 1, 6, tzinfo=dt.UTC)
    assert gps_to_utc(1_000_000_000).isoformat() == "2011-09-14T01:46:25+00:00"

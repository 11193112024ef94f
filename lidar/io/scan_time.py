"""When a scan file says it was scanned: the default date of a new epoch.

Only what the file itself records counts: the GPS time of a LAS/LAZ file's points (when the header
says they are adjusted standard GPS time), an E57 scan's ``acquisitionStart``, else the LAS header's
creation day. Formats without a time (PLY, PCD, PTX, text) give None; so does a time before 1990 (a
zero or a placeholder, not a survey).
"""
from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass
from pathlib import Path

from lidar.io import sniff_format
from lidar.io.e57 import acquisition_starts
from lidar.io.las import first_point_time, open_las

GPS_EPOCH = dt.datetime(1980, 1, 6, tzinfo=dt.UTC)
#: GPS - UTC in seconds from each date on (the leap seconds since the GPS epoch).
GPS_UTC_OFFSET = ((dt.date(1981, 7, 1), 1), (dt.date(1982, 7, 1), 2), (dt.date(1983, 7, 1), 3),
                  (dt.date(1985, 7, 1), 4), (dt.date(1988, 1, 1), 5), (dt.date(1990, 1, 1), 6),
                  (dt.date(1991, 1, 1), 7), (dt.date(1992, 7, 1), 8), (dt.date(1993, 7, 1), 9),
                  (dt.date(1994, 7, 1), 10), (dt.date(1996, 1, 1), 11), (dt.date(1997, 7, 1), 12),
                  (dt.date(1999, 1, 1), 13), (dt.date(2006, 1, 1), 14), (dt.date(2009, 1, 1), 15),
                  (dt.date(2012, 7, 1), 16), (dt.date(2015, 7, 1), 17), (dt.date(2017, 1, 1), 18))
#: Earlier times are placeholders (a zero, a default), not a survey's.
EARLIEST = dt.datetime(1990, 1, 1, tzinfo=dt.UTC)


@dataclass(frozen=True)
class ScanTime:
    """A scan's time (UTC) and where it came from; ``day_only`` when only the date is known."""

    when: dt.datetime
    source: str
    day_only: bool = False


def gps_to_utc(gps_seconds: float) -> dt.datetime:
    """UTC of a GPS time (seconds since 1980-01-06, no leap seconds).

    >>> gps_to_utc(1_000_000_000).isoformat()  # the GPS billennium, with 15 leap seconds
    '2011-09-14T01:46:25+00:00'
    """
    approx = GPS_EPOCH + dt.timedelta(seconds=float(gps_seconds))
    leap = 0
    for day, offset in GPS_UTC_OFFSET:
        if approx.date() >= day:
            leap = offset
    return approx - dt.timedelta(seconds=leap)


def _plausible(when: dt.datetime) -> bool:
    return EARLIEST <= when <= dt.datetime.now(dt.UTC) + dt.timedelta(days=2)


def _las_time(p: Path) -> ScanTime | None:
    las = open_las(p)
    if las.gps_time_type == 1:  # adjusted standard GPS time
        first = first_point_time(las)
        if first is not None:
            when = gps_to_utc(first + 1e9)
            if _plausible(when):
                return ScanTime(when.replace(microsecond=0), "the GPS time of its first point")
    day = las.creation_date
    if day is not None:
        when = dt.datetime(day.year, day.month, day.day, tzinfo=dt.UTC)
        if _plausible(when):
            return ScanTime(when, "the LAS header's creation day", day_only=True)
    return None


def _e57_time(p: Path) -> ScanTime | None:
    for start in acquisition_starts(p):
        if start is not None:
            when = gps_to_utc(start)
            if _plausible(when):
                return ScanTime(when.replace(microsecond=0), "the E57 scan's acquisitionStart")
    return None


def scan_file_time(path: str | os.PathLike) -> ScanTime | None:
    """When the scan file says it was scanned, or None (no time in the file, or the file unreadable).

    Never raises for a damaged file: the import itself reports that, in its own words.
    """
    p = Path(path)
    try:
        fmt = sniff_format(p)
        if fmt in ("las", "laz"):
            return _las_time(p)
        if fmt == "e57":
            return _e57_time(p)
    except Exception:  # noqa: BLE001 - any reader failure means "the file gives no time"
        return None
    return None

"""Check a LAS/LAZ header against the file before any library trusts it.

A damaged or hostile header can claim billions of points or VLRs in a file of
a few kilobytes; handed to laspy as it is, such a file allocates tens of
gigabytes or loops for minutes. :func:`check_las_header` reads the public
header block and walks the VLR and EVLR chains itself, bounded by the file's
size, and raises :class:`~lidar.ScanFormatError` naming the field that cannot
be true. Only a header that passes is opened with laspy.

Layout (ASPRS LAS 1.0-1.4): a public header block (227 bytes up to 1.2, 235
in 1.3, 375 in 1.4), then VLRs (54-byte header + payload) up to the offset to
point data, then the point records, then (1.4) the EVLRs (60-byte header +
payload).
"""
from __future__ import annotations

import datetime as dt
import math
import struct
from dataclasses import dataclass
from pathlib import Path

from common.errors import ScanFormatError

#: Minimum public header size by minor version.
HEADER_SIZES = {0: 227, 1: 227, 2: 227, 3: 235, 4: 375}
#: Minimum record length of each point data format (0-10).
POINT_RECORD_SIZES = (20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67)
VLR_HEADER = 54
EVLR_HEADER = 60
LASZIP_USER_ID = b"laszip encoded"
LASZIP_RECORD_ID = 22204
#: LAZ never compresses point records by more than this (real data: 4-15x). A
#: header claiming more points than this allows is refused before decoding.
MAX_LAZ_RATIO = 1000


@dataclass(frozen=True)
class LasHeaderFacts:
    """What a checked LAS header claims (all of it possible for the file's size)."""

    version: str
    point_format: int
    record_length: int
    point_count: int
    offset_to_points: int
    vlr_count: int
    evlr_count: int
    compressed: bool
    scales: tuple[float, ...]
    offsets: tuple[float, ...]
    file_size: int
    #: (x, y, z) bounds the header declares, metres
    mins: tuple[float, ...] = (0.0, 0.0, 0.0)
    maxs: tuple[float, ...] = (0.0, 0.0, 0.0)
    #: the header's creation day, None when it gives none (a zero year or day)
    creation_date: dt.date | None = None
    global_encoding: int = 0
    #: the payload of BridgeSurvey's pose VLR (or EVLR), when the file has one
    pose_record: bytes | None = None


def _u(fmt: str, blob: bytes, at: int):
    return struct.unpack_from("<" + fmt, blob, at)[0]


def _records(p: Path, fh, kind: str, start: int, count: int, end: int):
    """Walk a VLR or EVLR chain, each record inside [start, end); yield each record's header bytes and position."""
    head_len, length_fmt = (VLR_HEADER, "H") if kind == "VLR" else (EVLR_HEADER, "Q")
    pos = start
    for k in range(count):
        fh.seek(pos)
        rh = fh.read(head_len)
        if len(rh) < head_len:
            raise ScanFormatError(p, f"LAS {kind} {k} is truncated")
        length = _u(length_fmt, rh, 20)
        if length > end - pos - head_len:
            raise ScanFormatError(p, f"LAS {kind} {k} claims {length} bytes, running past "
                                     f"{'the point data' if kind == 'VLR' else 'the end of the file'}")
        yield rh, pos + head_len
        pos += head_len + length


def check_las_header(path: str | Path) -> LasHeaderFacts:
    """Validate the header of a LAS/LAZ file against the file itself.

    Parameters
    ----------
    path : path-like
        The file (its first bytes must be ``LASF``).

    Returns
    -------
    LasHeaderFacts
        The header's claims, each one checked.

    Raises
    ------
    ScanFormatError
        Naming the first header field that the file cannot hold or that makes
        no sense (zero/NaN/infinite scale, record length too short for the
        point format, more points or VLRs than the file's bytes allow...).
    """
    p = Path(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(375)
        if len(head) < 227:
            raise ScanFormatError(p, f"truncated LAS header: {len(head)} bytes, at least 227 are needed")
        if head[:4] != b"LASF":
            raise ScanFormatError(p, "not a LAS file (it does not start with 'LASF')")
        major, minor = head[24], head[25]
        if major != 1 or minor > 4:
            raise ScanFormatError(p, f"LAS version field says {major}.{minor}; only 1.0-1.4 exist")
        header_size = _u("H", head, 94)
        if header_size < HEADER_SIZES[minor]:
            raise ScanFormatError(p, f"LAS header size field is {header_size} bytes; version 1.{minor} needs "
                                     f"at least {HEADER_SIZES[minor]}")
        if len(head) < min(header_size, 375) or header_size > size:
            raise ScanFormatError(p, f"truncated LAS header: the header size field says {header_size} bytes, "
                                     f"the file has {size}")
        offset_points = _u("I", head, 96)
        vlr_count = _u("I", head, 100)
        fmt_byte = head[104]
        record_length = _u("H", head, 105)
        legacy_count = _u("I", head, 107)
        scales = struct.unpack_from("<3d", head, 131)
        offsets = struct.unpack_from("<3d", head, 155)
        point_format = fmt_byte & 0x3F
        compressed_bit = bool(fmt_byte & 0x80)
        if offset_points < header_size or offset_points > size:
            raise ScanFormatError(p, f"LAS 'offset to point data' is {offset_points}; it must lie between the "
                                     f"header size {header_size} and the file size {size}")
        if point_format > 10:
            raise ScanFormatError(p, f"LAS point data format {point_format} does not exist (0-10)")
        if record_length < POINT_RECORD_SIZES[point_format]:
            raise ScanFormatError(p, f"LAS point record length {record_length} is shorter than point format "
                                     f"{point_format} needs ({POINT_RECORD_SIZES[point_format]} bytes)")
        for axis, s in zip("xyz", scales, strict=False):
            if not math.isfinite(s) or s == 0.0:
                raise ScanFormatError(p, f"LAS {axis} scale factor is {s!r}; it must be a finite non-zero number")
        for axis, o in zip("xyz", offsets, strict=False):
            if not math.isfinite(o):
                raise ScanFormatError(p, f"LAS {axis} offset is {o!r}; it must be finite")
        count = legacy_count
        evlr_start = evlr_count = 0
        if minor >= 4:
            evlr_start = _u("Q", head, 235)
            evlr_count = _u("I", head, 243)
            count64 = _u("Q", head, 247)
            if count64:
                count = count64
            if legacy_count and count64 and legacy_count != count64:
                raise ScanFormatError(p, f"LAS point counts disagree: legacy field {legacy_count}, "
                                         f"64-bit field {count64}")
        # VLRs must lie between the header and the point data.
        room = offset_points - header_size
        if vlr_count > room // VLR_HEADER:
            raise ScanFormatError(p, f"LAS header claims {vlr_count} VLRs; the {room} bytes before the point "
                                     f"data hold at most {room // VLR_HEADER}")
        laszip = False
        pose_record = None
        for vh, at in list(_records(p, fh, "VLR", header_size, vlr_count, offset_points)):
            laszip |= vh[2:18].rstrip(b"\0") == LASZIP_USER_ID and _u("H", vh, 18) == LASZIP_RECORD_ID
            pose_record = _pose_record(fh, vh, at, "H") or pose_record
        compressed = compressed_bit or laszip
        if compressed_bit and not laszip:
            raise ScanFormatError(p, "the point format says LAZ-compressed but the file has no LASzip VLR")
        data_end = size
        if evlr_count:
            if evlr_start < offset_points or evlr_start > size:
                raise ScanFormatError(p, f"LAS 'start of first EVLR' is {evlr_start}, outside the file "
                                         f"({offset_points}-{size})")
            if evlr_count > (size - evlr_start) // EVLR_HEADER:
                raise ScanFormatError(p, f"LAS header claims {evlr_count} EVLRs; the file holds at most "
                                         f"{(size - evlr_start) // EVLR_HEADER}")
            for vh, at in list(_records(p, fh, "EVLR", evlr_start, evlr_count, size)):
                pose_record = _pose_record(fh, vh, at, "Q") or pose_record
            data_end = evlr_start
    data_bytes = data_end - offset_points
    if compressed:
        if count * record_length > MAX_LAZ_RATIO * max(data_bytes, 1):
            raise ScanFormatError(p, f"LAZ header claims {count} points, more than {data_bytes} bytes of "
                                     f"compressed data can hold")
    elif count * record_length > data_bytes:
        raise ScanFormatError(p, f"truncated or lying LAS header: it claims {count} points of {record_length} "
                                 f"bytes, but the file holds {max(data_bytes, 0) // record_length} after the header")
    return LasHeaderFacts(
        version=f"{major}.{minor}", point_format=point_format, record_length=record_length, point_count=count,
        offset_to_points=offset_points, vlr_count=vlr_count, evlr_count=evlr_count, compressed=compressed,
        scales=tuple(scales), offsets=tuple(offsets), file_size=size,
        mins=(_u("d", head, 187), _u("d", head, 203), _u("d", head, 219)),
        maxs=(_u("d", head, 179), _u("d", head, 195), _u("d", head, 211)),
        creation_date=_day(_u("H", head, 92), _u("H", head, 90)), global_encoding=_u("H", head, 6),
        pose_record=pose_record,
    )


#: The VLR in which BridgeSurvey's writer keeps a scan's pose (:mod:`lidar.io.las`).
POSE_USER_ID = b"BridgeSurvey"
POSE_RECORD_ID = 4401


def _pose_record(fh, rh: bytes, at: int, length_fmt: str) -> bytes | None:
    """The payload of a record that is BridgeSurvey's pose (128 bytes), else None."""
    if rh[2:18].rstrip(b"\0") != POSE_USER_ID or _u("H", rh, 18) != POSE_RECORD_ID or _u(length_fmt, rh, 20) != 128:
        return None
    fh.seek(at)
    data = fh.read(128)
    return data if len(data) == 128 else None


def _day(year: int, day_of_year: int) -> dt.date | None:
    """A creation day as laspy reads it: None for a year or day that makes no date."""
    try:
        return dt.date(year, 1, 1) + dt.timedelta(day_of_year - 1)
    except (ValueError, OverflowError):
        return None

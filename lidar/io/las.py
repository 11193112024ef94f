"""LAS and LAZ (1.0-1.4, every point format): the one reader and writer of the format.

Every path that reads a LAS/LAZ file goes through this module:

* :func:`open_las` checks the header against the file (:mod:`lidar.io.las_header`) and says what it holds
  (pose, dimensions, bounds, creation day, GPS time type) without reading a point;
* :func:`read_las` reads the whole scan: uncompressed LAS through :class:`LasRecords`, scaled chunk by chunk
  straight into the output arrays (the peak memory is the output plus a chunk), LAZ decoded in chunks by
  laspy's lazrs backend (parallel where available);
* :func:`las_point_chunks` yields the point records of any LAS/LAZ file chunk by chunk, :func:`las_blocks`
  a few runs of them, :func:`first_point_time` the time of the first point;
* :class:`LasRecords` maps an uncompressed file's point records window by window (the reader and the coarse
  map read them through it).

:func:`write_las` writes a scan; :func:`las_header_for` is the header of every LAS file BridgeSurvey writes
(LAS 1.4 point format 6, its pose in a VLR) and :func:`open_las_writer` writes point records chunk by chunk.
"""
from __future__ import annotations

import datetime as dt
import mmap
import os
import struct
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import ScanFormatError
from common.progress import ProgressCallback, report
from lidar.io._common import atomic_output, check_readable, first_line, make_scan, raw_for_writing
from lidar.io.las_header import POSE_RECORD_ID, POSE_USER_ID, LasHeaderFacts, check_las_header
from lidar.scan import Scan

#: VLR in which BridgeSurvey keeps the scanner pose (SOCS -> project frame) of a scan (read by check_las_header).
POSE_VLR_USER_ID = POSE_USER_ID.decode()
POSE_VLR_RECORD_ID = POSE_RECORD_ID

#: Points per chunk: small for LAS (buffers stay in cache); for LAZ, lazrs parallelises inside a chunk over its
#: 50 k point LAZ chunks, and holds Python's lock while it decodes: 262 k points keep both cores busy and the
#: application's interface thread waiting at most about 0.1 s (1 M points held it 0.3-0.4 s a chunk, for no gain:
#: 1.16 M points read in 0.42 s against 0.53 s, best of 6).
LAS_CHUNK_POINTS = 262_144
LAZ_CHUNK_POINTS = 262_144


def _laspy():
    """laspy, imported when a LAS/LAZ file is read through it (its import pulls requests in: a CLI start-up cost)."""
    # local: laspy (and the requests it imports) costs plan-file and info 0.08-0.12 s of start-up (measured)
    import laspy

    return laspy


def _laz_backend():
    available = _laspy().LazBackend.detect_available()
    return available[0] if available else None


def _errors() -> tuple[type[BaseException], ...]:
    """What laspy and the file system raise on a damaged file."""
    return _laspy().errors.LaspyException, ValueError, OSError, RuntimeError, struct.error


#: The point formats (0-10) whose records hold ``gps_time``, and where (bytes into the record).
GPS_TIME_OFFSET = {1: 20, 3: 20, 4: 20, 5: 20, 6: 22, 7: 22, 8: 22, 9: 22, 10: 22}


@dataclass(frozen=True, eq=False)
class LasFile:
    """A LAS/LAZ file whose header was checked against the file, and what the header says.

    Read from the header's bytes (:func:`lidar.io.las_header.check_las_header`): laspy is imported only
    for what needs it (the dimension names, laspy's header to copy records with, LAZ decoding).

    Attributes
    ----------
    path : Path
    facts : LasHeaderFacts
        The checked header fields.
    pose : (4, 4) float64 array or None
        The scanner pose BridgeSurvey's own writer stores (SOCS -> project frame).
    """

    path: Path
    facts: LasHeaderFacts
    pose: np.ndarray | None

    @property
    def points(self) -> int:
        return self.facts.point_count

    @property
    def compressed(self) -> bool:
        return self.facts.compressed

    @property
    def scales(self) -> np.ndarray:
        return np.asarray(self.facts.scales, np.float64)

    @property
    def offsets(self) -> np.ndarray:
        return np.asarray(self.facts.offsets, np.float64)

    @property
    def has_time(self) -> bool:
        """The point format has a ``gps_time`` field."""
        return self.facts.point_format in GPS_TIME_OFFSET

    @property
    def gps_time_type(self) -> int:
        """1 when the points' ``gps_time`` is adjusted standard GPS time, 0 for GPS week time."""
        return self.facts.global_encoding & 1

    @property
    def creation_date(self) -> dt.date | None:
        return self.facts.creation_date

    @property
    def mins(self) -> tuple[float, ...]:
        return self.facts.mins

    @property
    def maxs(self) -> tuple[float, ...]:
        return self.facts.maxs

    @cached_property
    def header(self) -> Any:
        """The header as laspy reads it (to write records with the input's header, :func:`point_records`)."""
        laspy = _laspy()
        try:
            with laspy.open(self.path, laz_backend=_laz_backend()) as reader:
                header = reader.header
        except _errors() as exc:
            raise ScanFormatError(self.path, f"not a readable LAS/LAZ file ({first_line(exc)})") from exc
        if int(header.point_count) != self.points:
            raise ScanFormatError(self.path, f"LAS point count unclear: {int(header.point_count)} read, "
                                             f"{self.points} checked")
        return header

    @property
    def dimensions(self) -> tuple[str, ...]:
        """The point format's dimension names (``"X"``, ``"intensity"``, ``"gps_time"``, extra bytes...)."""
        return tuple(self.header.point_format.dimension_names)


def open_las(path: str | os.PathLike) -> LasFile:
    """Check a LAS/LAZ file's header against the file and read what it says, without reading points.

    Raises
    ------
    ScanFormatError
        Not a LAS/LAZ file, a header that lies about the file (:mod:`lidar.io.las_header`), or no points.
    """
    p = check_readable(path)
    facts = check_las_header(p)  # refuse lying headers before laspy allocates or loops on them
    if facts.point_count == 0:
        raise ScanFormatError(p, "the LAS header declares 0 points; nothing to read")
    pose = np.array(struct.unpack("<16d", facts.pose_record)).reshape(4, 4) if facts.pose_record else None
    return LasFile(p, facts, pose)


def read_las(path: str | os.PathLike, *, progress: ProgressCallback | None = None,
             chunk_points: int | None = None) -> Scan:
    """Read a LAS or LAZ file into a :class:`Scan`.

    Parameters
    ----------
    path : path-like
        The .las or .laz file.
    progress : callable, optional
        ``progress(fraction, message)``.
    chunk_points : int, keyword-only
        Points decoded per chunk (memory/speed trade-off). Default 262,144 for
        LAS and 1,000,000 for LAZ.

    Returns
    -------
    Scan with float64 xyz in the file's frame (taken as SOCS), intensity
    normalised over the file, the raw uint16 intensity, the pose stored by
    BridgeSurvey's own writer, if any, and the point times (``time_s``) from
    ``gps_time`` when the point format has it and the times are not all zero
    (``metadata["has_time"]`` says which; a format with ``gps_time`` written
    without times holds zeros there).

    Raises
    ------
    ScanFormatError
        Not a LAS/LAZ file, corrupt or truncated, or without points.
    """
    las = open_las(path)
    p, n = las.path, las.points
    xyz = np.empty((n, 3), dtype=np.float64)
    raw = np.empty(n, dtype=np.uint16)
    times = np.empty(n, dtype=np.float64) if las.has_time else None
    out = (xyz, raw, times)
    try:
        if las.compressed:
            start = 0
            for records in las_point_chunks(las, chunk_points or LAZ_CHUNK_POINTS):
                _scale_into(out, start, records, las.scales, las.offsets)
                start += len(records)
                report(progress, start / n, "decoding LAZ")
        else:
            _decode_las(las, out, chunk_points or LAS_CHUNK_POINTS, progress)
    except ScanFormatError:
        raise
    except _errors() as exc:
        raise ScanFormatError(p, f"not a readable LAS/LAZ file ({first_line(exc)})") from exc
    if times is not None and not np.any(times):
        times = None  # the format has the field but the writer left it empty
    meta = {
        "version": las.facts.version,
        "point_format": las.facts.point_format,
        "scales": tuple(float(s) for s in las.scales),
        "offsets": tuple(float(o) for o in las.offsets),
        "compressed": las.compressed,
        "point_count": n,
        "has_time": times is not None,
    }
    # Scaled 32-bit integers are always finite: skip the (costly) finiteness scan.
    return make_scan(p, xyz, raw, fmt="LAZ" if las.compressed else "LAS", pose=las.pose, metadata=meta,
                     finite=True, time_s=times)


def _scale_into(out_arrays, start, records: np.ndarray, scales, offsets):
    """Scale the X, Y, Z integers of packed point records into ``xyz[start:]``, copy the intensity (and times).

    ``out_arrays`` is (xyz, raw, times); times is None when they are not read.

    Converting each field into a contiguous float64 temporary, scaling it there
    and then storing it into the (strided) output column is about twice as fast
    as letting numpy cast straight into the strided column.
    """
    xyz, raw, times = out_arrays
    m = records.shape[0]
    out = xyz[start:start + m]
    for k, name in enumerate(("X", "Y", "Z")):
        tmp = records[name].astype(np.float64)
        tmp *= scales[k]
        tmp += offsets[k]
        out[:, k] = tmp
    raw[start:start + m] = records["intensity"]
    if times is not None:
        times[start:start + m] = records["gps_time"]


def _decode_las(las: LasFile, out_arrays, chunk_points: int, progress: ProgressCallback | None) -> None:
    """Scale the point records chunk by chunk on two threads (the page faults of one overlap the other's work)."""
    n = las.points
    records = LasRecords(las, dtype=_scaled_fields(las))
    try:
        def work(start: int) -> int:
            stop = min(start + chunk_points, n)
            _scale_into(out_arrays, start, records.records(start, stop), las.scales, las.offsets)
            return stop

        with ThreadPoolExecutor(max_workers=2) as pool:
            for done in pool.map(work, range(0, n, chunk_points)):
                report(progress, done / n, "reading LAS")
    finally:
        records.close()


def _scaled_fields(las: LasFile) -> np.dtype:
    """The record dtype of the fields :func:`read_las` reads: X, Y, Z, the intensity (and ``gps_time``)."""
    names, formats, offsets = ["X", "Y", "Z", "intensity"], ["<i4", "<i4", "<i4", "<u2"], [0, 4, 8, 12]
    if las.has_time:
        names.append("gps_time")
        formats.append("<f8")
        offsets.append(GPS_TIME_OFFSET[las.facts.point_format])
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": las.facts.record_length})


#: Every LAS point format (0-10) starts X, Y, Z (int32) and the intensity (uint16).
def xyz_intensity_dtype(record_length: int) -> np.dtype:
    """The record dtype that reads only X, Y, Z (as 12 raw bytes, ``xyz``) and the intensity of each record."""
    return np.dtype({"names": ["xyz", "intensity"], "formats": ["V12", "<u2"], "offsets": [0, 12],
                     "itemsize": record_length})


class LasRecords:
    """An uncompressed LAS file's point records, mapped from the page cache window by window.

    The file stays open until :meth:`close` is called.

    Parameters
    ----------
    las : LasFile
        An uncompressed file (:func:`open_las`).
    dtype : numpy dtype, keyword-only
        The record type the records are viewed as (its size is the file's record length); default: only
        X, Y, Z and the intensity (:func:`xyz_intensity_dtype`).
    """

    def __init__(self, las: LasFile, *, dtype: np.dtype | None = None):
        if las.compressed:
            raise ScanFormatError(las.path, "LAZ point records are compressed; they cannot be mapped")
        self.las, self.path, self.n = las, las.path, las.points
        self.first = las.facts.offset_to_points
        self.dtype = dtype if dtype is not None else xyz_intensity_dtype(las.facts.record_length)
        if self.dtype.itemsize != las.facts.record_length:
            raise ValueError(f"a record of {self.dtype.itemsize} bytes for records of {las.facts.record_length}")
        self.fd = os.open(self.path, os.O_RDONLY)

    def close(self) -> None:
        os.close(self.fd)

    def raw(self, start: int, stop: int) -> np.ndarray:
        """Records ``start`` to ``stop`` as raw bytes, mapped read-only from the file (unmapped when dropped).

        A plain mapping: the threads that read the records fault the pages in, 16 at a fault and both threads at
        once. A copy (``preadv``) cost 0.04 s a pass of a 532 MB file, and windows mapped at once
        (``MAP_POPULATE``) were populated under the address space's lock, the other thread's mappings waiting:
        0.04 s more for the map of that file. A window at a time keeps the resident memory to a few chunks.
        """
        size = self.dtype.itemsize
        begin, end = self.first + start * size, self.first + stop * size
        if os.fstat(self.fd).st_size < end:  # shortened since its header was read: a mapping would crash
            raise ScanFormatError(self.path, "truncated: the point records end early")
        base = begin - begin % mmap.ALLOCATIONGRANULARITY
        try:
            window = mmap.mmap(self.fd, end - base, flags=mmap.MAP_SHARED, prot=mmap.PROT_READ, offset=base)
        except OSError:  # a file system that cannot map files: read a copy
            copy = np.empty(end - begin, np.uint8)
            if os.preadv(self.fd, [copy], begin) != copy.size:  # type: ignore[list-item]
                raise ScanFormatError(self.path, "truncated: the point records end early") from None
            return copy
        return np.frombuffer(window, np.uint8, count=end - begin, offset=begin - base)

    def records(self, start: int, stop: int) -> np.ndarray:
        """Records ``start`` to ``stop`` viewed as :attr:`dtype` (a view of the mapping)."""
        return self.raw(start, stop).view(self.dtype)


def las_point_chunks(las: LasFile, chunk_points: int) -> Iterator[np.ndarray]:
    """The point records of a LAS or LAZ file, ``chunk_points`` at a time, as laspy's structured arrays.

    Raises
    ------
    ScanFormatError
        Damaged point data, or fewer or more points than the header declares.
    """
    laspy = _laspy()
    done = 0
    try:
        with laspy.open(las.path, laz_backend=_laz_backend()) as reader:
            for pts in reader.chunk_iterator(chunk_points):
                rec = pts.array
                if done + len(rec) > las.points:
                    raise ScanFormatError(las.path, "holds more points than its header declares")
                done += len(rec)
                yield rec
    except ScanFormatError:
        raise
    except _errors() as exc:
        raise ScanFormatError(las.path, f"damaged point data after {done} points ({first_line(exc)})") from exc
    if done != las.points:
        raise ScanFormatError(las.path, f"truncated: the header declares {las.points} points but only {done} "
                                        "could be read")


def las_blocks(las: LasFile, starts: list[int], block_points: int) -> list[np.ndarray]:
    """Runs of ``block_points`` consecutive point records from each of ``starts`` (laspy's structured arrays)."""
    laspy = _laspy()
    out = []
    try:
        with laspy.open(las.path, laz_backend=_laz_backend()) as reader:
            for st in starts:
                reader.seek(st)
                out.append(reader.read_points(block_points).array)
    except _errors() as exc:
        raise ScanFormatError(las.path, f"damaged point data ({first_line(exc)})") from exc
    return out


def scaled_xyz(las: LasFile, records: np.ndarray) -> np.ndarray:
    """(m, 3) float64 coordinates, metres, of laspy point records (``X``, ``Y``, ``Z`` scaled and offset)."""
    xyz = np.empty((len(records), 3))
    scales, offsets = las.scales, las.offsets
    for k, name in enumerate(("X", "Y", "Z")):
        xyz[:, k] = records[name] * scales[k] + offsets[k]
    return xyz


def first_point_time(las: LasFile) -> float | None:
    """The ``gps_time`` of the file's first point (seconds, as the file stores it), or None when it has none."""
    if not las.has_time:
        return None
    return float(las_blocks(las, [0], 1)[0]["gps_time"][0])


def las_header_for(lo: np.ndarray, scale_m: float, pose: np.ndarray | None) -> Any:
    """The laspy header of every LAS file BridgeSurvey writes: LAS 1.4 point format 6, its pose in a VLR.

    ``lo`` is the offset (metres), ``scale_m`` the coordinate resolution.
    """
    laspy = _laspy()
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = lo
    header.scales = np.array([scale_m] * 3)
    if pose is not None:
        header.vlrs.append(
            laspy.VLR(user_id=POSE_VLR_USER_ID, record_id=POSE_VLR_RECORD_ID,
                      description="SOCS pose 4x4 float64",
                      record_data=struct.pack("<16d", *np.asarray(pose, dtype=np.float64).ravel()))
        )
    return header


def las_scale_for(lo: np.ndarray, hi: np.ndarray) -> float:
    """The coordinate resolution of a written file: 0.01 mm, coarsened ten-fold while the extent overflows int32."""
    extent = float(np.max(np.asarray(hi) - np.asarray(lo)))
    scale_m = 1e-5
    while extent / scale_m > 2.0e9:
        scale_m *= 10
    return scale_m


def open_las_writer(path: str | os.PathLike, header: Any, *, compress: bool) -> Any:
    """A laspy writer of point records with ``header`` (LAZ when ``compress``), a context manager."""
    return _laspy().open(path, mode="w", header=header, do_compress=compress,
                         laz_backend=_laz_backend() if compress else None)


def point_records(las: LasFile, records: np.ndarray) -> Any:
    """The laspy point records of ``las``'s point format holding ``records`` (from :func:`las_point_chunks`)."""
    return _laspy().PackedPointRecord(records, las.header.point_format)


def zero_records(header: Any, n: int) -> Any:
    """``n`` zeroed point records of ``header``'s format, their x, y, z settable in metres."""
    return _laspy().ScaleAwarePointRecord.zeros(n, header=header)


def write_las(scan: Scan, path: str | os.PathLike, *, scale_m: float | None = None) -> Path:
    """Write a scan as LAS or LAZ (chosen by the suffix), LAS 1.4 point format 6.

    Point format 6 has ``gps_time``: the scan's ``time_s`` goes there (seconds); a scan without
    times leaves it 0 for every point, as before times were written.

    Parameters
    ----------
    scan : Scan
    path : path-like
        Destination; ``.laz`` compresses. Written to a temporary name and renamed.
    scale_m : float, optional, keyword-only
        Coordinate resolution. Default 0.01 mm (1e-5 m), coarsened automatically
        only if the extent would overflow the 32-bit integers.

    Returns
    -------
    Path of the written file.
    """
    final = Path(path)
    xyz = scan.xyz_socs
    lo = np.floor(xyz.min(axis=0)) if len(scan) else np.zeros(3)
    if scale_m is None:
        scale_m = las_scale_for(lo, xyz.max(axis=0) if len(scan) else lo)
    las = _laspy().LasData(las_header_for(lo, scale_m, scan.pose))
    las.x = xyz[:, 0]
    las.y = xyz[:, 1]
    las.z = xyz[:, 2]
    raw = raw_for_writing(scan)
    if raw.dtype != np.uint16 and raw.size and np.all((raw >= 0) & (raw <= 65535) & (raw == np.round(raw))):
        raw = raw.astype(np.uint16)  # whole numbers in the 16-bit range are stored as they are
    elif raw.dtype != np.uint16:
        raw64 = raw.astype(np.float64)
        lo_i, hi_i = float(raw64.min()), float(raw64.max())
        raw = np.round((raw64 - lo_i) / (hi_i - lo_i) * 65535 if hi_i > lo_i else raw64 * 0).astype(np.uint16)
    las.intensity = raw
    if scan.time_s is not None:
        las.gps_time = scan.time_s
    compress = final.suffix.lower() == ".laz"
    with atomic_output(final) as tmp:
        las.write(tmp, do_compress=compress, laz_backend=_laz_backend() if compress else None)
    return final

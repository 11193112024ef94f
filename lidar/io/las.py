"""LAS and LAZ (1.2-1.4, every point format) reading and writing.

Uncompressed LAS is memory-mapped and scaled chunk by chunk straight into the
output arrays, so the peak memory is the output plus one chunk. LAZ is decoded
in chunks by laspy's lazrs backend (parallel where available).
"""
from __future__ import annotations

import os
import struct
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from common.errors import ScanFormatError
from common.progress import ProgressCallback, report
from lidar.io._common import atomic_output, check_readable, first_line, make_scan, raw_for_writing
from lidar.io.las_header import check_las_header
from lidar.scan import Scan

#: VLR in which BridgeSurvey keeps the scanner pose (SOCS -> project frame) of a scan.
POSE_VLR_USER_ID = "BridgeSurvey"
POSE_VLR_RECORD_ID = 4401

#: Points per chunk: small for LAS (buffers stay in cache), larger for LAZ (lazrs parallelises inside a chunk).
LAS_CHUNK_POINTS = 262_144
LAZ_CHUNK_POINTS = 1_000_000


def _laspy():
    """laspy, imported when a LAS/LAZ file is read through it (its import pulls requests in: a CLI start-up cost)."""
    import laspy

    return laspy


def _laz_backend():
    available = _laspy().LazBackend.detect_available()
    return available[0] if available else None


def _pose_from_header(header) -> np.ndarray | None:
    for vlr in list(header.vlrs) + list(getattr(header, "evlrs", None) or []):
        if getattr(vlr, "user_id", "") == POSE_VLR_USER_ID and getattr(vlr, "record_id", None) == POSE_VLR_RECORD_ID:
            data = getattr(vlr, "record_data", b"")
            if len(data) == 128:
                return np.array(struct.unpack("<16d", data)).reshape(4, 4)
    return None


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
    p = check_readable(path)
    facts = check_las_header(p)  # refuse lying headers before laspy allocates or loops on them
    laspy = _laspy()
    try:
        with laspy.open(p, laz_backend=_laz_backend()) as reader:
            header = reader.header
            n = int(header.point_count)
            if n != facts.point_count:
                raise ScanFormatError(p, f"LAS point count unclear: {n} read, {facts.point_count} checked")
            if n == 0:
                raise ScanFormatError(p, "the LAS header declares 0 points; nothing to read")
            scales = np.asarray(header.scales, dtype=np.float64)
            offsets = np.asarray(header.offsets, dtype=np.float64)
            xyz = np.empty((n, 3), dtype=np.float64)
            raw = np.empty(n, dtype=np.uint16)
            times = np.empty(n, dtype=np.float64) if "gps_time" in header.point_format.dimension_names else None
            compressed = header.are_points_compressed
            if compressed:
                chunk_points = chunk_points or LAZ_CHUNK_POINTS
                _decode_laz(reader, p, (xyz, raw, times), scales, offsets, chunk_points, progress)
            else:
                chunk_points = chunk_points or LAS_CHUNK_POINTS
                _decode_las(p, header, (xyz, raw, times), scales, offsets, chunk_points, progress)
            pose = _pose_from_header(header)
            if times is not None and not np.any(times):
                times = None  # the format has the field but the writer left it empty
            meta = {
                "version": str(header.version),
                "point_format": int(header.point_format.id),
                "scales": tuple(float(s) for s in scales),
                "offsets": tuple(float(o) for o in offsets),
                "compressed": bool(compressed),
                "point_count": n,
                "has_time": times is not None,
            }
    except ScanFormatError:
        raise
    except (laspy.errors.LaspyException, ValueError, OSError, RuntimeError, struct.error) as exc:
        raise ScanFormatError(p, f"not a readable LAS/LAZ file ({first_line(exc)})") from exc
    # Scaled 32-bit integers are always finite: skip the (costly) finiteness scan.
    return make_scan(p, xyz, raw, fmt="LAZ" if compressed else "LAS", pose=pose, metadata=meta, finite=True,
                     time_s=times)


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


def _decode_las(p: Path, header, out_arrays, scales, offsets, chunk_points, progress):
    """Read point records chunk by chunk with two threads (I/O of one overlaps scaling of the other).

    Peak memory is the output arrays plus one record buffer per thread.
    """
    n = out_arrays[0].shape[0]
    dtype = header.point_format.dtype()
    first = int(header.offset_to_point_data)
    size = p.stat().st_size
    if size < first + n * dtype.itemsize:
        have = max(0, (size - first) // dtype.itemsize)
        raise ScanFormatError(p, f"truncated: the header declares {n} points but the file holds only {have}")
    local = threading.local()
    fd = os.open(p, os.O_RDONLY)

    def work(start: int) -> int:
        m = min(chunk_points, n - start)
        buf = getattr(local, "buf", None)
        if buf is None or buf.size < chunk_points * dtype.itemsize:
            buf = local.buf = np.empty(chunk_points * dtype.itemsize, np.uint8)
        view = buf[: m * dtype.itemsize]
        got = os.preadv(fd, [view], first + start * dtype.itemsize)  # type: ignore[list-item]
        if got != view.size:
            raise ScanFormatError(p, "truncated: the point records end early")
        _scale_into(out_arrays, start, view.view(dtype), scales, offsets)
        return start + m

    try:
        with ThreadPoolExecutor(max_workers=2) as pool:
            for done in pool.map(work, range(0, n, chunk_points)):
                report(progress, done / n, "reading LAS")
    finally:
        os.close(fd)


def _decode_laz(reader, p: Path, out_arrays, scales, offsets, chunk_points, progress):
    """Decode LAZ chunk by chunk.

    lazrs decompresses each chunk on all cores, holding the GIL, so a prefetch thread would gain nothing.
    """
    n = out_arrays[0].shape[0]
    start = 0
    for chunk in reader.chunk_iterator(chunk_points):
        m = len(chunk)
        if start + m > n:
            raise ScanFormatError(p, "holds more points than its header declares")
        _scale_into(out_arrays, start, chunk.array, scales, offsets)
        start += m
        report(progress, start / n, "decoding LAZ")
    if start != n:
        raise ScanFormatError(p, f"truncated: the header declares {n} points but only {start} could be decoded")


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
    extent = float(np.max(xyz.max(axis=0) - lo)) if len(scan) else 0.0
    if scale_m is None:
        scale_m = 1e-5
        while extent / scale_m > 2.0e9:
            scale_m *= 10
    laspy = _laspy()
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = lo
    header.scales = np.array([scale_m] * 3)
    if scan.pose is not None:
        header.vlrs.append(
            laspy.VLR(user_id=POSE_VLR_USER_ID, record_id=POSE_VLR_RECORD_ID,
                      description="SOCS pose 4x4 float64",
                      record_data=struct.pack("<16d", *np.asarray(scan.pose, dtype=np.float64).ravel()))
        )
    las = laspy.LasData(header)
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

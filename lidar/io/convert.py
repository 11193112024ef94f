"""Converting scan files chunk by chunk, in memory bounded by the chunk whatever the file's size.

* LAS/LAZ to LAS/LAZ copies the point records with the input's header (every dimension, VLR and the pose
  kept; only the compression changes): lossless.
* Any other pair reads the input twice through :mod:`lidar.io.stream`: a first pass for what the output's
  header needs (valid point count, bounds, intensity range), a second that writes chunk by chunk. The
  outputs are those of the whole-scan writers (:func:`lidar.io.write_scan`): LAS 1.4 point format 6 at
  0.01 mm, binary PLY and PCD, XYZ and PTS text.
* E57 and PTX outputs, and inputs without fixed-size records (ASCII PLY/PCD, compressed PCD, PTX, PTS, XYZ),
  go through the whole-scan reader and writers: their memory grows with the scan.
"""
from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from common.errors import InputError, ScanFormatError
from common.files import atomic_output
from common.pcd import binary_pcd_header
from common.progress import ProgressCallback, report
from lidar.io import read_scans, write_scan
from lidar.io._common import pose_to_text
from lidar.io.e57 import write_e57
from lidar.io.las import (
    las_header_for,
    las_point_chunks,
    las_scale_for,
    open_las_writer,
    point_records,
    zero_records,
)
from lidar.io.pcd import pcd_viewpoint
from lidar.io.ply import POSE_COMMENT
from lidar.io.stream import CHUNK_POINTS, Chunk, ScanStream, open_stream

#: Outputs written chunk by chunk.
STREAMED_SUFFIXES = (".las", ".laz", ".ply", ".pcd", ".xyz", ".txt", ".pts")


@dataclass(frozen=True)
class Converted:
    """What :func:`convert_file` wrote: points, scans, whether the pose was kept and whether it streamed."""

    path: Path
    points: int
    scans: int
    pose_kept: bool | None  # None: the input had no pose
    streamed: bool
    lossless_copy: bool


@dataclass
class _Pass1:
    n: int
    lo: np.ndarray
    hi: np.ndarray
    raw_dtype: np.dtype | None
    raw_lo: float
    raw_hi: float
    raw_integral: bool


def convert_file(src: str | os.PathLike, dst: str | os.PathLike, *, scan: int | None = None,
                 chunk_points: int = CHUNK_POINTS, progress: ProgressCallback | None = None) -> Converted:
    """Convert ``src`` to the format of ``dst``'s suffix, streaming where both formats allow it.

    Parameters
    ----------
    src, dst : path-like
    scan : int, optional, keyword-only
        Only this scan (0-based) of a multi-scan input.
    chunk_points : int, keyword-only
        Points per chunk (default one million).
    progress : callable, optional

    Returns
    -------
    Converted

    Raises
    ------
    InputError
        A multi-scan input to a single-scan format without ``scan``, or ``scan`` out of range.
    ScanFormatError
        The input cannot be read.
    """
    src, dst = Path(src), Path(dst)
    suffix = dst.suffix.lower()
    stream = open_stream(src)
    count = len(stream.scans)
    if scan is not None and not 0 <= scan < count:
        raise InputError(f"{src}: holds {count} scan(s); --scan must be 0-{count - 1}")
    indices = [scan] if scan is not None else list(range(count))
    if len(indices) > 1 and suffix != ".e57":
        raise InputError(f"{src}: holds {count} scans; convert to .e57 to keep them all, or pick one with --scan K")
    if suffix not in STREAMED_SUFFIXES or not stream.streamed:
        return _whole(src, dst, indices, stream)
    k = indices[0]
    pose = stream.scans[k].pose
    if stream.kind == "las" and suffix in (".las", ".laz"):
        n = _copy_las(stream, dst, chunk_points, progress)
        return Converted(dst, n, 1, None if pose is None else True, True, True)
    first = _first_pass(stream, k, chunk_points, progress)
    writer = {".las": _write_las, ".laz": _write_las, ".ply": _write_ply, ".pcd": _write_pcd,
              ".xyz": _write_xyz, ".txt": _write_xyz, ".pts": _write_xyz}[suffix]
    chunks = _progressed(stream.chunks(k, chunk_points), first.n, progress)
    with atomic_output(dst) as tmp:
        writer(tmp, suffix, chunks, first, pose)
    kept = None if pose is None else suffix != ".pts"
    return Converted(dst, first.n, 1, kept, True, False)


def _progressed(chunks: Iterator[Chunk], n: int, progress: ProgressCallback | None) -> Iterator[Chunk]:
    done = 0
    for c in chunks:
        done += len(c.xyz)
        report(progress, 0.5 + 0.5 * done / max(n, 1), "writing")
        yield c


def _whole(src: Path, dst: Path, indices: list[int], stream: ScanStream) -> Converted:
    scans = stream.loaded if stream.loaded is not None else read_scans(src)
    scans = [scans[i] for i in indices]
    if dst.suffix.lower() == ".e57":
        write_e57(scans, dst)
    else:
        write_scan(scans[0], dst)
    pose = scans[0].pose
    return Converted(dst, sum(len(s) for s in scans), len(scans),
                     None if pose is None else dst.suffix.lower() != ".pts", False, False)


def _copy_las(stream: ScanStream, dst: Path, chunk_points: int, progress: ProgressCallback | None) -> int:
    """Copy every point record with the input's header; laspy (de)compresses."""
    las = stream.details["las"]
    n = las.points
    done = 0
    compress = dst.suffix.lower() == ".laz"
    with atomic_output(dst) as tmp:
        with open_las_writer(tmp, las.header, compress=compress) as writer:
            for rec in las_point_chunks(las, chunk_points):
                writer.write_points(point_records(las, rec))
                done += len(rec)
                report(progress, done / max(n, 1), "converting")
    return done


def _first_pass(stream: ScanStream, k: int, chunk_points: int, progress: ProgressCallback | None) -> _Pass1:
    """Valid point count, bounds and the raw intensity's range for the output's header."""
    p = _Pass1(0, np.full(3, np.inf), np.full(3, -np.inf), None, np.inf, -np.inf, True)
    declared = stream.scans[k].points
    for c in stream.chunks(k, chunk_points):
        if len(c.xyz) == 0:
            continue
        p.n += len(c.xyz)
        np.minimum(p.lo, c.xyz.min(axis=0), out=p.lo)
        np.maximum(p.hi, c.xyz.max(axis=0), out=p.hi)
        if c.raw is not None and len(c.raw):
            p.raw_dtype = c.raw.dtype
            p.raw_lo, p.raw_hi = min(p.raw_lo, float(c.raw.min())), max(p.raw_hi, float(c.raw.max()))
            if p.raw_integral and c.raw.dtype.kind == "f":
                p.raw_integral = bool(np.all(c.raw == np.round(c.raw)))
        report(progress, 0.5 * p.n / max(declared, 1), "reading")
    if p.n == 0:
        raise ScanFormatError(stream.path, "holds no valid points")
    return p


def _raw_out(c: Chunk, first: _Pass1) -> np.ndarray:
    """The chunk's raw intensity as the whole-scan writers store it (zeros without one)."""
    if c.raw is None:
        return np.zeros(len(c.xyz), np.uint16)
    return c.raw


def _las_intensity(raw: np.ndarray, first: _Pass1) -> np.ndarray:
    """16-bit LAS intensity: whole numbers in 0..65535 as they are, anything else mapped over the file's range."""
    if raw.dtype == np.uint16:
        return raw
    if first.raw_integral and first.raw_lo >= 0 and first.raw_hi <= 65535:
        return raw.astype(np.uint16)
    span = first.raw_hi - first.raw_lo
    scaled = (raw.astype(np.float64) - first.raw_lo) / span * 65535 if span > 0 else np.zeros(len(raw))
    return np.round(scaled).astype(np.uint16)


def _write_las(tmp: Path, suffix: str, chunks: Iterator[Chunk], first: _Pass1, pose) -> None:
    lo = np.floor(first.lo)
    header = las_header_for(lo, las_scale_for(lo, first.hi), pose)
    with open_las_writer(tmp, header, compress=suffix == ".laz") as writer:
        for c in chunks:
            rec = zero_records(header, len(c.xyz))
            rec.x, rec.y, rec.z = c.xyz[:, 0], c.xyz[:, 1], c.xyz[:, 2]
            rec.intensity = _las_intensity(_raw_out(c, first), first)
            writer.write_points(rec)


def _raw_dtype(first: _Pass1) -> np.dtype:
    return np.dtype(np.uint16) if first.raw_dtype is None else np.dtype(first.raw_dtype)


def _write_ply(tmp: Path, suffix: str, chunks: Iterator[Chunk], first: _Pass1, pose) -> None:
    dt = _raw_dtype(first).newbyteorder("<")
    ply_type = {"u1": "uchar", "i1": "char", "u2": "ushort", "i2": "short", "u4": "uint", "i4": "int",
                "f4": "float", "f8": "double"}.get(dt.str[1:], None)
    if ply_type is None:
        dt, ply_type = np.dtype("<f8"), "double"
    head = ["ply", "format binary_little_endian 1.0"]
    if pose is not None:
        head.append(f"comment {POSE_COMMENT} {pose_to_text(pose)}")
    head += [f"element vertex {first.n}", "property double x", "property double y", "property double z",
             f"property {ply_type} intensity", "end_header"]
    rec_dt = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", dt)])
    with open(tmp, "wb") as fh:
        fh.write(("\n".join(head) + "\n").encode("ascii"))
        _records(fh, chunks, rec_dt, first)


def _records(fh: BinaryIO, chunks: Iterator[Chunk], rec_dt: np.dtype, first: _Pass1) -> None:
    for c in chunks:
        rec = np.empty(len(c.xyz), dtype=rec_dt)
        rec["x"], rec["y"], rec["z"] = c.xyz[:, 0], c.xyz[:, 1], c.xyz[:, 2]
        rec["intensity"] = _raw_out(c, first)
        fh.write(rec.tobytes())


def _write_pcd(tmp: Path, suffix: str, chunks: Iterator[Chunk], first: _Pass1, pose) -> None:
    rec_dt = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "<f4")])
    with open(tmp, "wb") as fh:
        fh.write(binary_pcd_header(rec_dt, first.n, viewpoint=pcd_viewpoint(pose)))
        _records(fh, chunks, rec_dt, first)


def _write_xyz(tmp: Path, suffix: str, chunks: Iterator[Chunk], first: _Pass1, pose) -> None:
    with open(tmp, "w", encoding="utf-8") as fh:
        if suffix == ".pts":
            fh.write(f"{first.n}\n")
        else:
            if pose is not None:
                fh.write("# pose " + pose_to_text(pose) + "\n")
            fh.write("//X Y Z Intensity\n")
        for c in chunks:
            np.savetxt(fh, np.column_stack([c.xyz, _raw_out(c, first).astype(np.float64)]),
                       fmt="%.5f %.5f %.5f %.6g")

"""Reading and writing scan files.

:func:`read_scans` reads any supported file into a list of :class:`~lidar.Scan`
(E57 and PTX files may hold several set-ups); :func:`read_scan` returns the one
scan of a single-set-up file; :func:`write_scan` writes by file suffix.

Supported: LAS/LAZ 1.0-1.4 (every point format, COPC, EVLRs), E57, PLY, PCD,
PTX, PTS and ASCII XYZ with intensity. Every header is checked against the
file's size before anything is allocated; anything unreadable raises
:class:`~lidar.ScanFormatError` naming the file and the problem.
"""
from __future__ import annotations

import os
from pathlib import Path

from common.errors import InputError, ScanFormatError
from common.progress import ProgressCallback
from lidar.io._common import check_readable
from lidar.io.e57 import read_e57, write_e57
from lidar.io.las import read_las, write_las
from lidar.io.pcd import read_pcd, write_pcd
from lidar.io.ply import read_ply, write_ply
from lidar.io.ptx import read_ptx, write_ptx
from lidar.io.xyz import read_xyz, write_pts, write_xyz
from lidar.scan import Scan

READ_SUFFIXES = {".las": "las", ".laz": "las", ".e57": "e57", ".ply": "ply", ".pcd": "pcd", ".ptx": "ptx",
                 ".xyz": "xyz", ".txt": "xyz", ".asc": "xyz", ".pts": "xyz", ".csv": "xyz"}
WRITE_SUFFIXES = (".las", ".laz", ".e57", ".ply", ".pcd", ".ptx", ".pts", ".xyz", ".txt")


def sniff_format(path: str | os.PathLike) -> str:
    """Format key of a scan file from its first bytes, falling back to the suffix."""
    p = check_readable(path)
    with open(p, "rb") as fh:
        head = fh.read(64)
    if head.startswith(b"LASF"):
        return "las"
    if head.startswith(b"ASTM-E57"):
        return "e57"
    if head.startswith(b"ply"):
        return "ply"
    if b"PCD" in head[:16] or head.startswith(b"VERSION") or head.startswith(b"FIELDS"):
        return "pcd"
    kind = READ_SUFFIXES.get(p.suffix.lower())
    if kind in ("las", "e57", "ply", "pcd"):
        raise ScanFormatError(p, f"does not start like a {p.suffix.upper()[1:]} file (wrong or damaged file)")
    if kind is None:
        raise ScanFormatError(p, f"unsupported scan format '{p.suffix or '(no suffix)'}'; use LAS, LAZ, E57, PLY, PCD, PTX or XYZ")
    return kind


def read_scans(path: str | os.PathLike, *, progress: ProgressCallback | None = None) -> list[Scan]:
    """Read every scan of a file (one for most formats, possibly several for E57/PTX)."""
    kind = sniff_format(path)
    if kind == "las":
        return [read_las(path, progress=progress)]
    if kind == "e57":
        return read_e57(path, progress=progress)
    if kind == "ptx":
        return read_ptx(path)
    if kind == "ply":
        return [read_ply(path)]
    if kind == "pcd":
        return [read_pcd(path)]
    return [read_xyz(path)]


def read_scan(path: str | os.PathLike, *, progress: ProgressCallback | None = None) -> Scan:
    """Read a file holding exactly one scan (one scanner set-up)."""
    scans = read_scans(path, progress=progress)
    if len(scans) != 1:
        raise ScanFormatError(path, f"holds {len(scans)} scans (set-ups); choose one with read_scans()")
    return scans[0]


def write_scan(scan: Scan, path: str | os.PathLike) -> Path:
    """Write a scan in the format given by the path's suffix."""
    suffix = Path(path).suffix.lower()
    if suffix in (".las", ".laz"):
        return write_las(scan, path)
    if suffix == ".e57":
        return write_e57(scan, path)
    if suffix == ".ply":
        return write_ply(scan, path)
    if suffix == ".pcd":
        return write_pcd(scan, path)
    if suffix == ".ptx":
        return write_ptx(scan, path)
    if suffix in (".xyz", ".txt"):
        return write_xyz(scan, path)
    if suffix == ".pts":
        return write_pts(scan, path)
    raise InputError(f"{path}: cannot write '{suffix or '(no suffix)'}'; use one of {', '.join(WRITE_SUFFIXES)}")


__all__ = ["read_scan", "read_scans", "write_scan", "sniff_format", "read_las", "write_las", "read_e57",
           "write_e57", "read_ply", "write_ply", "read_pcd", "write_pcd", "read_ptx", "write_ptx",
           "read_xyz", "write_xyz", "write_pts"]

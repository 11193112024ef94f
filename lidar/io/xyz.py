"""ASCII point files: XYZ/TXT/ASC/CSV (x y z [intensity ...]) and Leica PTS.

Values may be separated by blanks, tabs, commas or semicolons. An optional
header line naming the columns (``//X,Y,Z,Intensity``, ``X Y Z
scalar_Intensity``...) picks the coordinate and intensity columns by name (see
:mod:`lidar.io.names`); without one the first three columns are x, y, z and
the fourth is intensity. A PTS file starts with a line holding its point
count, which is checked against the lines present. Lines are parsed by pandas'
C reader, so memory stays near the decoded arrays.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from common.errors import ScanFormatError
from lidar.io._common import (
    atomic_output,
    check_readable,
    make_scan,
    pose_from_text,
    pose_to_text,
    raw_for_writing,
    read_ascii_table,
)
from lidar.io.names import find_column
from lidar.scan import Scan

_SPLIT = re.compile(r"[\s,;]+")
#: Lines looked at for a header before the first numeric line.
MAX_HEADER_LINES = 50


def _tokens(line: str) -> list[str]:
    return [t for t in _SPLIT.split(line.strip()) if t]


def _is_numeric(tokens: list[str]) -> bool:
    try:
        float(tokens[0])
    except (ValueError, IndexError):
        return False
    return True


def read_xyz(path: str | os.PathLike) -> Scan:
    """Read an ASCII XYZ(+intensity) or PTS file.

    Raises
    ------
    ScanFormatError
        Binary content, no numeric lines, fewer than three columns, malformed
        lines, or a PTS count the file does not hold.
    """
    p = check_readable(path)
    names: list[str] | None = None
    declared: int | None = None
    pose = None
    with open(p, "rb") as fh:
        skip = 0
        offset = 0
        sample = ""
        while True:
            raw_line = fh.readline(1 << 16)
            if not raw_line:
                raise ScanFormatError(p, "the file holds no point lines")
            if b"\0" in raw_line:
                raise ScanFormatError(p, "not a text point file (binary content)")
            try:
                line = raw_line.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise ScanFormatError(p, "not a text point file (binary content)") from exc
            toks = _tokens(line)
            if toks and _is_numeric(toks) and not line.lstrip().startswith(("#", "//")):
                if len(toks) == 1 and declared is None and skip == 0:  # PTS: the point count alone on a line
                    try:
                        declared = int(toks[0])
                    except ValueError as exc:
                        raise ScanFormatError(p, f"first line '{toks[0][:20]}' is neither a header nor a "
                                                 "PTS point count") from exc
                    if declared < 0:
                        raise ScanFormatError(p, f"PTS point count {declared} is negative")
                    skip += 1
                    offset = fh.tell()
                    continue
                sample = line
                break
            if line.lstrip().startswith(("# pose", "//pose")):
                pose = _pose_line(p, toks)
            elif toks:
                names = toks
            skip += 1
            offset = fh.tell()
            if skip > MAX_HEADER_LINES:
                raise ScanFormatError(p, f"no numeric point lines in the first {MAX_HEADER_LINES} lines")
        size = p.stat().st_size
        if declared is not None and declared * 6 > size - offset + 1:  # "0 0 0\n" is the shortest point line
            raise ScanFormatError(p, f"truncated or lying PTS header: it declares {declared} points, the file "
                                     f"has room for at most {(size - offset + 1) // 6}")
        sep = "," if "," in sample else (";" if ";" in sample else r"\s+")
        ncols = len(_tokens(sample))
        fh.seek(offset)
        table = read_ascii_table(p, fh, sep=sep, nrows=declared, ncols=ncols, what="point line")
    if table.shape[0] == 0:
        raise ScanFormatError(p, "the file holds no points")
    if table.shape[1] < 3:
        raise ScanFormatError(p, f"each line needs at least x y z, found {table.shape[1]} column(s)")
    if declared is not None and table.shape[0] < declared:
        raise ScanFormatError(p, f"truncated: the PTS header declares {declared} points, the file holds {table.shape[0]}")
    cols = [0, 1, 2]
    ci = 3 if table.shape[1] >= 4 else None
    if names and len(names) == table.shape[1]:
        found = [find_column(names, a) for a in ("x", "y", "z")]
        if None not in found:
            cols = [int(c) for c in found if c is not None]
        ci = find_column(names, "intensity")
        if ci is None and table.shape[1] >= 4 and names[3].lower() not in ("r", "red"):
            ci = 3
    raw = table[:, ci] if ci is not None else None
    fmt = "PTS" if declared is not None else "XYZ"
    return make_scan(p, table[:, cols], raw, fmt=fmt, pose=pose, metadata={"columns": names or []})


def _pose_line(p: Path, toks: list[str]) -> np.ndarray:
    """The 4x4 pose of a ``# pose`` header line written by :func:`write_xyz` (16 numbers, row by row)."""
    vals = [t for t in toks if t not in ("#", "//", "pose", "#pose", "//pose", "pose:")]
    return pose_from_text(p, vals, "pose header line")


def write_xyz(scan: Scan, path: str | os.PathLike) -> Path:
    """Write ``x y z intensity`` lines (0.01 mm, raw intensity) with a header line."""
    final = Path(path)
    raw = raw_for_writing(scan).astype(np.float64)
    with atomic_output(final) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            if scan.pose is not None:
                fh.write("# pose " + pose_to_text(scan.pose) + "\n")
            fh.write("//X Y Z Intensity\n")
            np.savetxt(fh, np.column_stack([scan.xyz_socs, raw]), fmt="%.5f %.5f %.5f %.6g")
    return final


def write_pts(scan: Scan, path: str | os.PathLike) -> Path:
    """Write a Leica PTS file: the point count, then ``x y z intensity`` lines."""
    final = Path(path)
    raw = raw_for_writing(scan).astype(np.float64)
    with atomic_output(final) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(f"{len(scan)}\n")
            np.savetxt(fh, np.column_stack([scan.xyz_socs, raw]), fmt="%.5f %.5f %.5f %.6g")
    return final

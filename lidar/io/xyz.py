"""ASCII point files: x y z [intensity ...], space-, comma-, semicolon- or tab-separated.

An optional header line naming the columns (e.g. ``//X,Y,Z,Intensity``) picks
the intensity column by name; without one the fourth column is intensity.
"""
from __future__ import annotations

import io
import os
import re
from pathlib import Path

import numpy as np

from lidar.errors import ScanFormatError
from lidar.io._common import atomic_output, first_line, check_readable, make_scan, raw_for_writing
from lidar.scan import Scan

_SPLIT = re.compile(r"[\s,;]+")
_INTENSITY = ("intensity", "scalar_intensity", "i", "reflectance", "int", "amplitude")


def _is_numeric(line: str) -> bool:
    tokens = _SPLIT.split(line.strip())
    try:
        float(tokens[0])
    except ValueError:
        return False
    return True


def read_xyz(path: str | os.PathLike) -> Scan:
    """Read an ASCII XYZ(+intensity) file."""
    p = check_readable(path)
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ScanFormatError(p, "not a text point file (binary content)") from exc
    lines = text.splitlines()
    names: list[str] | None = None
    first = 0
    while first < len(lines) and not _is_numeric(lines[first]):
        if lines[first].strip():
            names = [t.strip().lower() for t in _SPLIT.split(lines[first].lstrip("/#").strip()) if t.strip()]
        first += 1
        if first > 50:
            raise ScanFormatError(p, "no numeric point lines found")
    sample = next((ln for ln in lines[first:first + 5] if ln.strip()), "")
    delim = "," if "," in sample else (";" if ";" in sample else None)
    try:
        table = np.loadtxt(io.StringIO("\n".join(lines[first:])), dtype=np.float64, delimiter=delim, ndmin=2,
                           comments=("#", "//"))
    except ValueError as exc:
        raise ScanFormatError(p, f"malformed point line ({first_line(exc)})") from exc
    if table.size == 0:
        raise ScanFormatError(p, "the file holds no points")
    if table.shape[1] < 3:
        raise ScanFormatError(p, f"each line needs at least x y z, found {table.shape[1]} column(s)")
    col = 3 if table.shape[1] >= 4 else None
    if names and len(names) == table.shape[1]:
        named = [k for k, nm in enumerate(names) if nm in _INTENSITY]
        col = named[0] if named else (3 if table.shape[1] >= 4 and names[3] not in ("r", "red") else None)
    raw = table[:, col] if col is not None else None
    return make_scan(p, table[:, :3], raw, fmt="XYZ", metadata={"columns": names or []})


def write_xyz(scan: Scan, path: str | os.PathLike) -> Path:
    """Write ``x y z intensity`` lines (0.01 mm, raw intensity) with a header line."""
    final = Path(path)
    raw = raw_for_writing(scan).astype(np.float64)
    with atomic_output(final) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write("//X Y Z Intensity\n")
            np.savetxt(fh, np.column_stack([scan.xyz_socs, raw]), fmt="%.5f %.5f %.5f %.6g")
    return final

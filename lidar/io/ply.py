"""PLY point clouds (ASCII and binary) with intensity, through plyfile.

The header is read and checked here first: the element counts it claims
against the bytes present (binary: count x row size; ASCII: at least one short
line per row), so plyfile never allocates for rows that are not there. Header
variants other tools write are accepted: trailing blanks (``ply ``), CRLF line
ends, ``comment`` and ``obj_info`` lines, list properties, CloudCompare's
``scalar_`` fields and property names in any case.
"""
from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from plyfile import PlyData
from plyfile import PlyElement as PlyfileElement

from common.errors import ScanFormatError
from lidar.io._common import (
    atomic_output,
    check_readable,
    first_line,
    make_scan,
    pose_from_text,
    pose_to_text,
    raw_for_writing,
)
from lidar.io.names import find_column
from lidar.scan import Scan

MAX_HEADER_BYTES = 65536
_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
          "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}
_END = re.compile(rb"end_header[ \t]*\r?\n")


@dataclass(frozen=True)
class PlyElement:
    """One element of a PLY header (``vertex``...): its name, count and properties."""

    name: str
    count: int
    min_row_bytes: int  # binary: exact for scalar rows, a lower bound with lists
    properties: tuple[str, ...]


def check_ply_header(p: Path, head: bytes) -> tuple[str, list[PlyElement], int, bytes]:
    """Parse a PLY header: (format, elements, data offset, header normalised for plyfile)."""
    m = _END.search(head)
    if not head.startswith(b"ply") or m is None:
        if head.startswith(b"ply"):
            raise ScanFormatError(p, "damaged PLY header (no end_header line in the first 64 kB)")
        raise ScanFormatError(p, "not a PLY file (it does not start with 'ply')")
    lines = [ln.strip() for ln in head[:m.start()].decode("latin-1").split("\n")]
    if lines[0] != "ply":
        raise ScanFormatError(p, f"not a PLY file (first line '{lines[0][:20]}')")
    fmt = ""
    elements: list[list] = []
    clean = ["ply"]
    for ln in lines[1:]:
        if not ln:
            continue
        words = ln.split()
        key = words[0]
        if key in ("comment", "obj_info"):
            clean.append(ln)
            continue
        if key == "format":
            if len(words) < 2 or words[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise ScanFormatError(p, f"unsupported PLY format line '{ln[:40]}'")
            fmt = words[1]
        elif key == "element":
            try:
                count = int(words[2])
            except (IndexError, ValueError) as exc:
                raise ScanFormatError(p, f"PLY element line '{ln[:40]}' has no valid count") from exc
            if count < 0:
                raise ScanFormatError(p, f"PLY element {words[1]} has a negative count {count}")
            elements.append([words[1], count, 0, []])
        elif key == "property":
            if not elements:
                raise ScanFormatError(p, "PLY property line before any element")
            if len(words) >= 5 and words[1] == "list":
                if words[2] not in _SIZES or words[3] not in _SIZES:
                    raise ScanFormatError(p, f"PLY list property '{ln[:40]}' has an unknown type")
                elements[-1][2] += _SIZES[words[2]]
                elements[-1][3].append(words[4])
            elif len(words) == 3 and words[1] in _SIZES:
                elements[-1][2] += _SIZES[words[1]]
                elements[-1][3].append(words[2])
            else:
                raise ScanFormatError(p, f"malformed PLY property line '{ln[:40]}'")
        else:
            raise ScanFormatError(p, f"unknown PLY header line '{ln[:40]}'")
        clean.append(" ".join(words))
    if not fmt:
        raise ScanFormatError(p, "the PLY header has no format line")
    clean.append("end_header")
    els = [PlyElement(n, c, b, tuple(props)) for n, c, b, props in elements]
    return fmt, els, m.end(), ("\n".join(clean) + "\n").encode("latin-1")


def read_ply(path: str | os.PathLike) -> Scan:
    """Read the ``vertex`` element of a PLY file (x, y, z and an intensity-like property)."""
    p = check_readable(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)
    fmt, elements, data_start, clean = check_ply_header(p, head)
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise ScanFormatError(p, "the PLY file has no 'vertex' element")
    cols = [find_column(vertex.properties, a) for a in ("x", "y", "z")]
    if None in cols:
        raise ScanFormatError(p, "the PLY vertex element has no x, y, z properties")
    body = size - data_start
    need = sum(e.count * (e.min_row_bytes if fmt != "ascii" else 2 * max(len(e.properties), 1)) for e in elements)
    if need > body + 1:
        raise ScanFormatError(p, f"truncated or lying PLY header: its elements need at least {need} bytes, "
                                 f"the file has {body} after the header")
    if vertex.count == 0:
        raise ScanFormatError(p, "the PLY vertex element declares 0 points; nothing to read")
    try:
        if clean == head[:data_start]:
            ply = PlyData.read(str(p))
        else:  # a header variant plyfile does not take: hand it the normalised header and the same data
            with open(p, "rb") as fh:
                fh.seek(data_start)
                ply = PlyData.read(io.BytesIO(clean + fh.read()))
        data = ply["vertex"].data
    except ScanFormatError:
        raise
    except Exception as exc:  # plyfile raises many types for malformed input
        raise ScanFormatError(p, f"not a readable PLY file ({first_line(exc)})") from exc
    names = data.dtype.names or ()
    if len(data) != vertex.count:
        raise ScanFormatError(p, f"truncated: the PLY header declares {vertex.count} points, {len(data)} were read")
    xyz_cols = [c for c in (find_column(names, a) for a in ("x", "y", "z")) if c is not None]
    if len(xyz_cols) != 3:
        raise ScanFormatError(p, "the PLY vertex data has no x, y, z columns")
    xyz = np.column_stack([data[names[c]] for c in xyz_cols]).astype(np.float64)
    ci = find_column(names, "intensity")
    raw = np.asarray(data[names[ci]]) if ci is not None else None
    return make_scan(p, xyz, raw, fmt="PLY", pose=_pose_comment(p, clean),
                     metadata={"ply_format": fmt, "properties": list(names)})


POSE_COMMENT = "bridgesurvey_pose"


def _pose_comment(p: Path, header: bytes):
    """The scanner pose BridgeSurvey keeps in a ``comment bridgesurvey_pose`` line (16 numbers), if any."""
    for line in header.decode("latin-1").split("\n"):
        words = line.split()
        if words[:2] == ["comment", POSE_COMMENT]:
            return pose_from_text(p, words[2:], "PLY pose comment")
    return None


def write_ply(scan: Scan, path: str | os.PathLike, *, binary: bool = True) -> Path:
    """Write x, y, z (float64) and the raw intensity as a PLY vertex element."""
    final = Path(path)
    raw = raw_for_writing(scan)
    rec = np.empty(len(scan), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", raw.dtype.str)])
    rec["x"], rec["y"], rec["z"] = scan.xyz_socs.T
    rec["intensity"] = raw
    comments = []
    if scan.pose is not None:
        comments.append(POSE_COMMENT + " " + pose_to_text(scan.pose))
    with atomic_output(final) as tmp:
        PlyData([PlyfileElement.describe(rec, "vertex")], text=not binary, comments=comments).write(str(tmp))
    return final

"""PCD (Point Cloud Library) files: ascii, binary and binary_compressed (LZF).

The header is parsed and checked here, so files written by PCL, PDAL, Open3D,
CloudCompare and pypcd all open: field names in any case (``X Y Z Intensity``
from PDAL), the usual intensity aliases, ASCII values separated by blanks,
tabs or commas. Every count the header claims (``POINTS``, ``WIDTH`` x
``HEIGHT``, the compressed and uncompressed sizes) is checked against the
bytes present before anything is allocated. LZF blocks are decoded by the C
codec PCL's own Python users rely on (``python-neo-lzf``, the ``lzf`` module
pypcd4 uses).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import lzf
import numpy as np

from common.errors import ScanFormatError
from common.pcd import NO_VIEWPOINT, binary_pcd_header
from lidar.io._common import (
    atomic_output,
    check_readable,
    make_scan,
    pose_from_quaternion,
    quaternion_from_pose,
    raw_for_writing,
    read_ascii_table,
)
from lidar.io.names import find_column
from lidar.scan import Scan

_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8",
          ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8"}
#: A PCD header is a few hundred bytes; more than this without a DATA line is not a PCD file.
MAX_HEADER_BYTES = 65536
#: Field counts (COUNT) above this are not point attributes (PCL's largest descriptor has 352).
MAX_FIELD_COUNT = 4096


@dataclass(frozen=True)
class PcdHeader:
    """The header of a PCD file: fields, sizes, types, counts, point count and data encoding."""

    fields: tuple[str, ...]
    sizes: tuple[int, ...]
    types: tuple[str, ...]
    counts: tuple[int, ...]
    points: int
    viewpoint: tuple[float, ...]
    mode: str
    data_start: int

    @property
    def row_bytes(self) -> int:
        return sum(s * c for s, c in zip(self.sizes, self.counts, strict=False))


def _ints(p: Path, key: str, values: list[str], n: int | None = None) -> list[int]:
    try:
        out = [int(v) for v in values]
    except ValueError as exc:
        raise ScanFormatError(p, f"PCD header field {key} is not a list of whole numbers ({' '.join(values)[:40]})") from exc
    if n is not None and len(out) != n:
        raise ScanFormatError(p, f"PCD header field {key} has {len(out)} entries for {n} fields")
    if any(v < 0 for v in out):
        raise ScanFormatError(p, f"PCD header field {key} is negative")
    return out


def parse_header(p: Path, head: bytes) -> PcdHeader:
    """Parse and check a PCD header (the bytes up to and including the DATA line)."""
    entries: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = head.find(b"\n", pos)
        if end < 0:
            raise ScanFormatError(p, "not a PCD file or a damaged header (no DATA line)")
        line = head[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        entries[key.upper()] = values
        if key.upper() == "DATA":
            break
    for key in ("FIELDS", "SIZE", "TYPE"):
        if key not in entries or not entries[key]:
            raise ScanFormatError(p, f"the PCD header has no {key} line")
    fields = tuple(entries["FIELDS"])
    nf = len(fields)
    sizes = _ints(p, "SIZE", entries["SIZE"], nf)
    types = tuple(t.upper() for t in entries["TYPE"])
    if len(types) != nf:
        raise ScanFormatError(p, f"PCD header field TYPE has {len(types)} entries for {nf} fields")
    counts = _ints(p, "COUNT", entries.get("COUNT", ["1"] * nf), nf)
    for f, s, t, c in zip(fields, sizes, types, counts, strict=False):
        if (t, s) not in _TYPES:
            raise ScanFormatError(p, f"PCD field {f} has an unsupported type {t}{s}")
        if not 1 <= c <= MAX_FIELD_COUNT:
            raise ScanFormatError(p, f"PCD field {f} has COUNT {c}; expected 1-{MAX_FIELD_COUNT}")
    if "WIDTH" in entries and "HEIGHT" in entries:
        width, height = _ints(p, "WIDTH", entries["WIDTH"], 1)[0], _ints(p, "HEIGHT", entries["HEIGHT"], 1)[0]
        grid = width * height
    else:
        grid = None
    if "POINTS" in entries:
        points = _ints(p, "POINTS", entries["POINTS"], 1)[0]
        if grid is not None and grid != points:
            raise ScanFormatError(p, f"PCD header disagrees with itself: POINTS {points}, WIDTH x HEIGHT {grid}")
    elif grid is not None:
        points = grid
    else:
        raise ScanFormatError(p, "the PCD header has neither POINTS nor WIDTH and HEIGHT")
    viewpoint: tuple[float, ...] = ()
    if "VIEWPOINT" in entries:
        try:
            viewpoint = tuple(float(v) for v in entries["VIEWPOINT"])
        except ValueError as exc:
            raise ScanFormatError(p, "PCD VIEWPOINT is not 7 numbers") from exc
        if len(viewpoint) != 7:
            raise ScanFormatError(p, f"PCD VIEWPOINT has {len(viewpoint)} numbers; it needs 7 (tx ty tz qw qx qy qz)")
    mode = (entries["DATA"] or [""])[0].lower()
    if mode not in ("ascii", "binary", "binary_compressed"):
        raise ScanFormatError(p, f"unsupported PCD DATA mode '{mode}' (ascii, binary or binary_compressed)")
    return PcdHeader(fields, tuple(sizes), types, tuple(counts), points, viewpoint, mode, pos)


def read_pcd(path: str | os.PathLike) -> Scan:
    """Read a PCD file's x, y, z and intensity, and its VIEWPOINT as the pose.

    Raises
    ------
    ScanFormatError
        A malformed header, counts the file cannot hold, a damaged LZF block,
        no x/y/z fields, or no valid points.
    """
    p = check_readable(path)
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)
    h = parse_header(p, head)
    cx, cy, cz = (find_column(h.fields, axis) for axis in ("x", "y", "z"))
    if cx is None or cy is None or cz is None:
        raise ScanFormatError(p, f"the PCD file has no x, y, z fields (fields: {' '.join(h.fields)[:80]})")
    ci = find_column(h.fields, "intensity")
    if h.points == 0:
        raise ScanFormatError(p, "the PCD header declares 0 points; nothing to read")
    body_bytes = size - h.data_start
    if h.mode == "ascii":
        cols = _read_ascii(p, h, body_bytes)
    elif h.mode == "binary":
        if h.points * h.row_bytes > body_bytes:
            raise ScanFormatError(p, f"truncated or lying PCD header: it declares {h.points} points of "
                                     f"{h.row_bytes} bytes, the file holds {body_bytes // max(h.row_bytes, 1)}")
        rec = np.fromfile(p, dtype=record_dtype(h), count=h.points, offset=h.data_start)
        cols = [rec[f"f{k}"] if h.counts[k] == 1 else rec[f"f{k}"][:, 0] for k in range(len(h.fields))]
    else:
        cols = _read_compressed(p, h, body_bytes)
    xyz = np.column_stack([cols[cx], cols[cy], cols[cz]]).astype(np.float64)
    raw_i = np.asarray(cols[ci]) if ci is not None else None
    pose = None
    if h.viewpoint:
        pose = pose_from_quaternion(h.viewpoint[3:], h.viewpoint[:3])
        if np.allclose(pose, np.eye(4)):
            pose = None
    return make_scan(p, xyz, raw_i, fmt="PCD", pose=pose,
                     metadata={"pcd_data": h.mode, "fields": list(h.fields)})


def record_dtype(h: PcdHeader) -> np.dtype:
    """The numpy record type of a binary PCD's points (fields named f0, f1...; a field of COUNT > 1 a sub-array)."""
    return np.dtype([(f"f{k}", _TYPES[(t, s)], (c,)) if c > 1 else (f"f{k}", _TYPES[(t, s)])
                     for k, (s, t, c) in enumerate(zip(h.sizes, h.types, h.counts, strict=False))])


def _read_ascii(p: Path, h: PcdHeader, body_bytes: int) -> list[np.ndarray]:
    ncols = sum(h.counts)
    if h.points * (2 * ncols) > body_bytes + 1:  # each value needs at least a digit and a separator
        raise ScanFormatError(p, f"truncated or lying PCD header: it declares {h.points} points, the ASCII data "
                                 f"has room for at most {(body_bytes + 1) // (2 * ncols)}")
    with open(p, "rb") as fh:
        fh.seek(h.data_start)
        first = fh.readline().decode("ascii", "replace")
        fh.seek(h.data_start)
        table = read_ascii_table(p, fh, sep="," if "," in first else r"\s+", nrows=h.points,
                                 what="PCD ASCII point line")
    if table.shape[0] < h.points:
        raise ScanFormatError(p, f"truncated: the PCD header declares {h.points} points, the file holds {table.shape[0]}")
    if table.shape[1] < ncols:
        raise ScanFormatError(p, f"PCD ASCII lines have {table.shape[1]} values; the header declares {ncols}")
    starts = np.cumsum((0,) + h.counts[:-1])
    return [table[:, s] for s in starts]


def _read_compressed(p: Path, h: PcdHeader, body_bytes: int) -> list[np.ndarray]:
    if body_bytes < 8:
        raise ScanFormatError(p, "truncated: the PCD compressed block has no size fields")
    with open(p, "rb") as fh:
        fh.seek(h.data_start)
        csize, usize = (int(v) for v in np.frombuffer(fh.read(8), dtype="<u4"))
        if csize > body_bytes - 8:
            raise ScanFormatError(p, f"truncated: the PCD compressed block claims {csize} bytes, "
                                     f"{body_bytes - 8} are present")
        if usize != h.points * h.row_bytes:
            raise ScanFormatError(p, f"PCD compressed block claims {usize} bytes once decompressed; "
                                     f"{h.points} points of {h.row_bytes} bytes need {h.points * h.row_bytes}")
        block = fh.read(csize)
    try:
        raw = lzf.decompress(block, usize) if usize else b""
    except ValueError as exc:
        raise ScanFormatError(p, f"damaged PCD compressed block ({exc})") from exc
    if raw is None or len(raw) != usize:
        raise ScanFormatError(p, f"damaged PCD compressed block (decodes to {0 if raw is None else len(raw)} "
                                 f"bytes, expected {usize})")
    cols, off = [], 0
    for s, t, c in zip(h.sizes, h.types, h.counts, strict=False):  # column-major: every value of a field, then the next
        width = s * c * h.points
        cols.append(np.frombuffer(raw, dtype=_TYPES[(t, s)], count=c * h.points, offset=off).reshape(h.points, c)[:, 0])
        off += width
    return cols


def write_pcd(scan: Scan, path: str | os.PathLike) -> Path:
    """Write a binary PCD with x, y, z as float64 and the raw intensity as float32."""
    final = Path(path)
    n = len(scan)
    raw = raw_for_writing(scan).astype(np.float32)
    rec = np.empty(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "<f4")])
    rec["x"], rec["y"], rec["z"] = scan.xyz_socs.T
    rec["intensity"] = raw
    with atomic_output(final) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(binary_pcd_header(rec.dtype, n, viewpoint=pcd_viewpoint(scan.pose)))
            fh.write(rec.tobytes())
    return final


def pcd_viewpoint(pose: np.ndarray | None) -> str:
    """A PCD ``VIEWPOINT`` (tx ty tz qw qx qy qz) of a scanner pose (SOCS -> project frame), or of none."""
    if pose is None:
        return NO_VIEWPOINT
    q, t = quaternion_from_pose(pose)
    return " ".join(f"{v:.12g}" for v in (*t, *q))

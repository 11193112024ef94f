"""PCD (Point Cloud Library) files: ascii, binary and binary_compressed (LZF)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lidar.errors import ScanFormatError
from lidar.io._common import atomic_output, check_readable, make_scan, pose_from_quaternion, quaternion_from_pose, raw_for_writing
from lidar.scan import Scan

_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8",
          ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8"}


def _parse_header(p: Path, blob: bytes) -> tuple[dict, int]:
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = blob.find(b"\n", pos)
        if end < 0:
            raise ScanFormatError(p, "PCD header ends before its DATA line")
        line = blob[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            return header, pos
        if len(header) > 32:
            raise ScanFormatError(p, "not a PCD file (no DATA line in the header)")


def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decompress an LZF block (the codec of PCD ``binary_compressed``)."""
    out = bytearray(size)
    i = o = 0
    n = len(data)
    while i < n:
        ctrl = data[i]
        i += 1
        if ctrl < 32:  # literal run
            length = ctrl + 1
            out[o:o + length] = data[i:i + length]
            i += length
            o += length
        else:  # back reference
            length = ctrl >> 5
            if length == 7:
                length += data[i]
                i += 1
            ref = o - ((ctrl & 0x1F) << 8) - data[i] - 1
            i += 1
            length += 2
            if ref < 0:
                raise ValueError("corrupt LZF stream")
            for k in range(length):  # may overlap: copy byte by byte
                out[o + k] = out[ref + k]
            o += length
    if o != size:
        raise ValueError(f"LZF stream decodes to {o} bytes, expected {size}")
    return bytes(out)


def read_pcd(path: str | os.PathLike) -> Scan:
    """Read a PCD file's x, y, z and intensity, and its VIEWPOINT as the pose."""
    p = check_readable(path)
    blob = p.read_bytes()
    try:
        header, start = _parse_header(p, blob)
        fields = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = header["TYPE"]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
        n = int(header["POINTS"][0]) if "POINTS" in header else int(header["WIDTH"][0]) * int(header["HEIGHT"][0])
        mode = header["DATA"][0].lower()
    except ScanFormatError:
        raise
    except (KeyError, ValueError, IndexError) as exc:
        raise ScanFormatError(p, f"not a PCD file or a malformed header ({exc})") from exc
    if not {"x", "y", "z"} <= set(fields):
        raise ScanFormatError(p, "the PCD file has no x, y, z fields")
    if n == 0:
        raise ScanFormatError(p, "the PCD header declares 0 points; nothing to read")
    try:
        dtype = np.dtype([(f, _TYPES[(t.upper(), s)], (c,)) if c > 1 else (f, _TYPES[(t.upper(), s)])
                          for f, s, t, c in zip(fields, sizes, types, counts)])
    except KeyError as exc:
        raise ScanFormatError(p, f"unsupported PCD field type {exc}") from exc
    body = blob[start:]
    try:
        if mode == "ascii":
            table = np.loadtxt(body.decode("ascii").splitlines(), dtype=np.float64, ndmin=2)
            if table.shape[0] < n:
                raise ScanFormatError(p, f"truncated: the header declares {n} points but the file holds {table.shape[0]}")
            cols = {}
            k = 0
            for f, c in zip(fields, counts):
                cols[f] = table[:n, k]
                k += c
        elif mode == "binary":
            if len(body) < n * dtype.itemsize:
                raise ScanFormatError(p, f"truncated: the header declares {n} points but the file holds {len(body) // dtype.itemsize}")
            rec = np.frombuffer(body, dtype=dtype, count=n)
            cols = {f: rec[f] for f in fields}
        elif mode == "binary_compressed":
            csize, usize = np.frombuffer(body[:8], dtype="<u4")
            raw = lzf_decompress(body[8:8 + int(csize)], int(usize))
            cols, off = {}, 0
            for f, s, t, c in zip(fields, sizes, types, counts):  # column-major layout
                width = s * c * n
                cols[f] = np.frombuffer(raw[off:off + width], dtype=_TYPES[(t.upper(), s)]).reshape(n, c)[:, 0]
                off += width
        else:
            raise ScanFormatError(p, f"unsupported PCD DATA mode '{mode}'")
    except ScanFormatError:
        raise
    except (ValueError, IndexError) as exc:
        raise ScanFormatError(p, f"corrupt PCD point data ({exc})") from exc
    xyz = np.column_stack([cols["x"], cols["y"], cols["z"]]).astype(np.float64)
    raw_i = next((np.asarray(cols[k]) for k in ("intensity", "Intensity", "reflectance") if k in cols), None)
    pose = None
    if "VIEWPOINT" in header and len(header["VIEWPOINT"]) == 7:
        v = [float(x) for x in header["VIEWPOINT"]]
        pose = pose_from_quaternion(v[3:], v[:3])
        if np.allclose(pose, np.eye(4)):
            pose = None
    return make_scan(p, xyz, raw_i, fmt="PCD", pose=pose, metadata={"pcd_data": mode})


def write_pcd(scan: Scan, path: str | os.PathLike) -> Path:
    """Write a binary PCD with x, y, z as float64 and the raw intensity as float32."""
    final = Path(path)
    n = len(scan)
    raw = raw_for_writing(scan).astype(np.float32)
    rec = np.empty(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "<f4")])
    rec["x"], rec["y"], rec["z"] = scan.xyz_socs.T
    rec["intensity"] = raw
    if scan.pose is not None:
        q, t = quaternion_from_pose(scan.pose)
        viewpoint = " ".join(f"{v:.12g}" for v in (*t, *q))
    else:
        viewpoint = "0 0 0 1 0 0 0"
    header = (
        "# .PCD v0.7 - written by BridgeSurvey\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 8 8 8 4\n"
        f"TYPE F F F F\nCOUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT {viewpoint}\nPOINTS {n}\nDATA binary\n"
    )
    with atomic_output(final) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(header.encode("ascii"))
            fh.write(rec.tobytes())
    return final

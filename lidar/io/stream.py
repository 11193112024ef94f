"""Scan files read chunk by chunk, with memory bounded by the chunk, for work that needs no whole scan.

:func:`open_stream` checks a file's header with the same checks as the readers (``lidar.io.las_header``,
``e57_header``, the PLY and PCD header parsers) and describes its scans; :meth:`ScanStream.chunks` then yields
the points of one scan as :class:`Chunk` (float64 xyz in the scanner frame and the raw intensity):

* LAS/LAZ through laspy's chunk iterator (lazrs decodes LAZ in parallel);
* E57 through libE57's block reader (pye57), spherical coordinates converted, invalid points dropped;
* binary PLY and binary PCD by memory-mapping their fixed-size records.

Other files (ASCII PLY/PCD, compressed PCD, PTX, PTS, XYZ) have no fixed-size records to map: they are read
whole by :func:`lidar.io.read_scans` and handed out in chunks (``ScanStream.streamed`` is False).
"""
from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.errors import ScanFormatError
from lidar.io import pcd, read_scans, sniff_format
from lidar.io._common import check_readable, first_line, pose_from_quaternion, quiet_stderr
from lidar.io.e57 import opened_e57
from lidar.io.e57_header import NS, check_e57, logical_bytes
from lidar.io.las import LasFile, las_blocks, las_point_chunks, open_las, scaled_xyz
from lidar.io.names import find_column
from lidar.io.pcd import record_dtype
from lidar.io.ply import MAX_HEADER_BYTES, POSE_COMMENT, check_ply_header

#: Points per chunk by default: about 50 MB of temporaries.
CHUNK_POINTS = 1_000_000


@dataclass(frozen=True)
class Chunk:
    """Consecutive points of one scan: (m, 3) float64 xyz (scanner frame, metres) and the raw intensity (m,)."""

    xyz: np.ndarray
    raw: np.ndarray | None


@dataclass(frozen=True)
class StreamScan:
    """What a file's header says of one of its scans, before any point is read.

    Attributes
    ----------
    name : str
    points : int
        Records the header declares (invalid E57 points are dropped while reading).
    pose : (4, 4) array or None
        Scanner frame -> file frame.
    intensity_limits : (lo, hi) or None
        A range the file declares for its intensity (E57 ``intensityLimits``).
    has_intensity : bool
    bounds : ((3,), (3,)) tuple or None
        Bounds the header declares, in the scanner frame (LAS header; E57 ``cartesianBounds`` when the
        scan has no pose), or None.
    """

    name: str
    points: int
    pose: np.ndarray | None
    intensity_limits: tuple[float, float] | None
    has_intensity: bool
    bounds: tuple[tuple[float, ...], tuple[float, ...]] | None = None


@dataclass
class ScanStream:
    """A checked scan file whose scans can be read chunk by chunk (see :func:`open_stream`)."""

    path: Path
    kind: str
    scans: list[StreamScan]
    streamed: bool
    details: dict = field(default_factory=dict)
    loaded: list | None = None  # the scans read whole, for files that cannot be streamed

    def chunks(self, index: int = 0, chunk_points: int = CHUNK_POINTS) -> Iterator[Chunk]:
        """Yield the points of scan ``index`` in chunks of at most ``chunk_points``."""
        self._check(index)
        reader = {"las": _las_chunks, "e57": _e57_chunks, "ply": _ply_chunks, "pcd": _pcd_chunks}.get(self.kind)
        if reader is None or not self.streamed:
            yield from _whole_scan_chunks(self._whole()[index], 0, None, chunk_points)
            return
        yield from reader(self, index, chunk_points)

    def sample_blocks(self, index: int = 0, *, blocks: int = 3, block_points: int = 60_000) -> list[Chunk]:
        """A few runs of consecutive points, spread over scan ``index`` (the first one only for E57).

        Consecutive points of a scanner's file are whole scan lines: what :mod:`lidar.io.angular_step` reads
        steps from, for a fraction of the cost of the whole file.
        """
        self._check(index)
        n = self.scans[index].points
        starts = sorted({int(v) for v in np.linspace(0, max(n - block_points, 0), blocks)})
        if self.kind == "las":
            return _las_blocks(self, starts, block_points)
        if self.kind == "e57" and self.streamed:
            return [next(iter(_e57_chunks(self, index, block_points, first_only=True)), Chunk(np.empty((0, 3)), None))]
        if self.kind in ("ply", "pcd") and self.streamed:
            rec, cols, icol = (_ply_records if self.kind == "ply" else _pcd_records)(self)
            return [c for st in starts for c in _record_chunks(rec[st:st + block_points], cols, icol, block_points)]
        if self.kind in ("ply", "pcd"):
            return []  # ASCII or compressed: no cheap way to a block in the middle
        scan = self._whole()[index]
        return [c for st in starts for c in _whole_scan_chunks(scan, st, st + block_points, block_points)]

    def _check(self, index: int) -> None:
        if not 0 <= index < len(self.scans):
            raise ScanFormatError(self.path, f"holds {len(self.scans)} scan(s); there is no scan {index}")

    def _whole(self) -> list:
        if self.loaded is None:
            self.loaded = read_scans(self.path)
        return self.loaded


def open_stream(path: str | os.PathLike) -> ScanStream:
    """Check a scan file's header and describe its scans without reading points.

    Raises
    ------
    ScanFormatError
        The header is damaged or lies about the file (the message names the file and the field).
    """
    p = check_readable(path)
    kind = sniff_format(p)
    opener = {"las": _open_las, "e57": _open_e57, "ply": _open_ply, "pcd": _open_pcd}.get(kind)
    if opener is not None:
        return opener(p)

    loaded = read_scans(p)  # PTX, PTS, XYZ: no header that tells the points; read whole
    scans = [StreamScan(s.name, len(s), s.pose, None, s.intensity_raw is not None) for s in loaded]
    meta = dict(loaded[0].metadata)
    return ScanStream(p, kind, scans, False, {"format": str(meta.get("format", kind.upper())),
                                              "version": str(meta.get("version", ""))}, loaded)


# ------------------------------------------------------------------ LAS / LAZ (lidar.io.las reads them)
def _open_las(p: Path) -> ScanStream:
    las = open_las(p)
    facts = las.facts
    details = {"format": "LAZ" if facts.compressed else "LAS", "version": facts.version,
               "point_format": facts.point_format, "record_length": facts.record_length,
               "scales": facts.scales, "offsets": facts.offsets, "compressed": facts.compressed,
               "dimensions": list(las.dimensions), "vlrs": facts.vlr_count, "evlrs": facts.evlr_count, "las": las}
    scan = StreamScan(p.stem, facts.point_count, las.pose, None, True, (las.mins, las.maxs))
    return ScanStream(p, "las", [scan], True, details)


def _las_chunk(las: LasFile, rec: np.ndarray) -> Chunk:
    return Chunk(scaled_xyz(las, rec), np.asarray(rec["intensity"]).copy())


def _las_chunks(s: ScanStream, index: int, chunk_points: int) -> Iterator[Chunk]:
    las = s.details["las"]
    for rec in las_point_chunks(las, chunk_points):
        yield _las_chunk(las, rec)


def _las_blocks(s: ScanStream, starts: list[int], block_points: int) -> list[Chunk]:
    las = s.details["las"]
    return [_las_chunk(las, rec) for rec in las_blocks(las, starts, block_points)]


# ------------------------------------------------------------------ E57
def _e57_xml(p: Path):
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(48)
        xml_off, xml_len = np.frombuffer(head[24:40], "<u8")
        return ET.fromstring(logical_bytes(p, fh, int(xml_off), int(xml_len), size))


def _e57_float(node, *names: str) -> float | None:
    for name in names:
        node = node.find(NS + name) if node is not None else None
    if node is None or node.text is None:
        return None
    try:
        return float(node.text)
    except ValueError:
        return None


def _open_e57(p: Path) -> ScanStream:
    facts = check_e57(p)
    if not facts.scans:
        if facts.images:
            raise ScanFormatError(p, f"the E57 file holds {facts.images} image(s) and no point scans; export the "
                                     "point cloud from the scanner software")
        raise ScanFormatError(p, "the E57 file holds no scans")
    root = _e57_xml(p)
    data3d = root.find(NS + "data3D")
    nodes = list(data3d) if data3d is not None else []
    scans = []
    for k, (f, node) in enumerate(zip(facts.scans, nodes, strict=False)):
        if f.record_count == 0:
            raise ScanFormatError(p, f"scan {k} ({f.name}) holds no points")
        q = [_e57_float(node, "pose", "rotation", a) for a in ("w", "x", "y", "z")]
        t = [_e57_float(node, "pose", "translation", a) for a in ("x", "y", "z")]
        pose = pose_from_quaternion([v if v is not None else (1.0 if i == 0 else 0.0) for i, v in enumerate(q)],
                                    [v or 0.0 for v in t])
        lo = _e57_float(node, "intensityLimits", "intensityMinimum")
        hi = _e57_float(node, "intensityLimits", "intensityMaximum")
        b = [_e57_float(node, "cartesianBounds", f"{a}{m}") for m in ("Minimum", "Maximum") for a in "xyz"]
        # cartesianBounds are in the file frame: scanner-frame bounds only when the pose is the identity
        bounds = ((b[0], b[1], b[2]), (b[3], b[4], b[5])) if None not in b and np.allclose(pose, np.eye(4)) else None
        scans.append(StreamScan(f.name or f"scan{k}", f.record_count, pose,
                                (lo, hi) if lo is not None and hi is not None and hi > lo else None,
                                "intensity" in f.fields, bounds))  # type: ignore[arg-type]
    return ScanStream(p, "e57", scans, True, {"format": "E57", "version": facts.version,
                                                "fields": [list(f.fields) for f in facts.scans],
                                                "images": facts.images})


_E57_FIELDS = ("cartesianX", "cartesianY", "cartesianZ", "cartesianInvalidState", "sphericalRange",
               "sphericalAzimuth", "sphericalElevation", "sphericalInvalidState", "intensity")


def _e57_chunks(s: ScanStream, index: int, chunk_points: int, *, first_only: bool = False) -> Iterator[Chunk]:
    done = 0
    with opened_e57(s.path) as e57:
        try:
            with quiet_stderr():
                header = e57.get_header(index)
                wanted = [f for f in header.point_fields if f in _E57_FIELDS]
                data, buffers = e57.make_buffers(wanted, min(chunk_points, header.point_count))
                reader = header.points.reader(buffers)
            try:
                while True:
                    with quiet_stderr():
                        got = reader.read()
                    if got == 0:
                        break
                    done += got
                    yield _e57_chunk(s.path, {k: v[:got] for k, v in data.items()})
                    if first_only:
                        return
            finally:
                reader.close()
        except ScanFormatError:
            raise
        except Exception as exc:
            raise ScanFormatError(s.path, f"corrupt E57 data after {done} points ({first_line(exc)})") from exc
    if done != s.scans[index].points:
        raise ScanFormatError(s.path, f"truncated: scan {index} declares {s.scans[index].points} points, {done} "
                                      "could be read")


def _e57_chunk(p: Path, data: dict) -> Chunk:
    if {"cartesianX", "cartesianY", "cartesianZ"} <= data.keys():
        xyz = np.column_stack([data["cartesianX"], data["cartesianY"], data["cartesianZ"]]).astype(np.float64)
        invalid = data.get("cartesianInvalidState")
    elif {"sphericalRange", "sphericalAzimuth", "sphericalElevation"} <= data.keys():
        r = np.asarray(data["sphericalRange"], np.float64)
        az = np.asarray(data["sphericalAzimuth"], np.float64)
        el = np.asarray(data["sphericalElevation"], np.float64)
        xyz = np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])
        invalid = data.get("sphericalInvalidState")
    else:
        raise ScanFormatError(p, "an E57 scan has neither cartesian nor spherical coordinates")
    raw = np.array(data["intensity"]) if "intensity" in data else None
    if invalid is not None:
        keep = np.asarray(invalid) == 0
        xyz, raw = xyz[keep], (raw[keep] if raw is not None else None)
    return Chunk(xyz, raw)


# ------------------------------------------------------------------ PLY / PCD (fixed-size binary records)
_PLY_TYPES = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2", "ushort": "u2",
              "int16": "i2", "uint16": "u2", "int": "i4", "uint": "u4", "int32": "i4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _open_ply(p: Path) -> ScanStream:
    with open(p, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES)
    fmt, elements, data_start, clean = check_ply_header(p, head)
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise ScanFormatError(p, "the PLY file has no 'vertex' element")
    if None in [find_column(vertex.properties, a) for a in ("x", "y", "z")]:
        raise ScanFormatError(p, "the PLY vertex element has no x, y, z properties")
    if vertex.count == 0:
        raise ScanFormatError(p, "the PLY vertex element declares 0 points; nothing to read")
    types = _ply_vertex_types(clean)
    mappable = fmt != "ascii" and elements[0].name == "vertex" and types is not None
    if mappable and data_start + vertex.count * vertex.min_row_bytes > p.stat().st_size:
        raise ScanFormatError(p, f"truncated: the PLY header declares {vertex.count} points, the file is shorter")
    pose = None
    for line in clean.decode("latin-1").split("\n"):
        words = line.split()
        if words[:2] == ["comment", POSE_COMMENT] and len(words) == 18:
            pose = np.array([float(v) for v in words[2:]]).reshape(4, 4)
    dtype = None
    if mappable and types is not None:
        order = "<" if fmt == "binary_little_endian" else ">"
        dtype = np.dtype([(n, order + t) for n, t in types])
    details = {"format": "PLY", "ply_format": fmt, "properties": list(vertex.properties), "data_start": data_start,
               "dtype": dtype}
    has_i = find_column(vertex.properties, "intensity") is not None
    return ScanStream(p, "ply", [StreamScan(p.stem, vertex.count, pose, None, has_i)], mappable, details)


def _ply_vertex_types(clean: bytes) -> list[tuple[str, str]] | None:
    """(name, numpy type) of the vertex element's scalar properties; None when it has a list property."""
    out: list[tuple[str, str]] = []
    inside = False
    for line in clean.decode("latin-1").split("\n"):
        w = line.split()
        if w[:1] == ["element"]:
            inside = w[1] == "vertex"
        elif inside and w[:1] == ["property"]:
            if w[1] == "list" or w[1] not in _PLY_TYPES:
                return None
            out.append((w[2], _PLY_TYPES[w[1]]))
    return out


def _ply_records(s: ScanStream) -> tuple[np.ndarray, list[str], str | None]:
    dtype = s.details["dtype"]
    rec = np.memmap(s.path, dtype=dtype, mode="r", offset=s.details["data_start"], shape=(s.scans[0].points,))
    names = dtype.names
    cols = [names[find_column(names, a)] for a in ("x", "y", "z")]
    ci = find_column(names, "intensity")
    return rec, cols, names[ci] if ci is not None else None


def _ply_chunks(s: ScanStream, index: int, chunk_points: int) -> Iterator[Chunk]:
    yield from _record_chunks(*_ply_records(s), chunk_points)


def _open_pcd(p: Path) -> ScanStream:
    with open(p, "rb") as fh:
        head = fh.read(pcd.MAX_HEADER_BYTES)
    h = pcd.parse_header(p, head)
    if None in [find_column(h.fields, a) for a in ("x", "y", "z")]:
        raise ScanFormatError(p, f"the PCD file has no x, y, z fields (fields: {' '.join(h.fields)[:80]})")
    if h.points == 0:
        raise ScanFormatError(p, "the PCD header declares 0 points; nothing to read")
    if h.mode == "binary" and h.points * h.row_bytes > p.stat().st_size - h.data_start:
        raise ScanFormatError(p, f"truncated or lying PCD header: it declares {h.points} points of {h.row_bytes} "
                                 "bytes, the file is shorter")
    pose = None
    if h.viewpoint:
        pose = pose_from_quaternion(h.viewpoint[3:], h.viewpoint[:3])
        if np.allclose(pose, np.eye(4)):
            pose = None
    has_i = find_column(h.fields, "intensity") is not None
    return ScanStream(p, "pcd", [StreamScan(p.stem, h.points, pose, None, has_i)], h.mode == "binary",
                      {"format": "PCD", "pcd_data": h.mode, "fields": list(h.fields), "header": h})


def _pcd_records(s: ScanStream) -> tuple[np.ndarray, list[str], str | None]:
    h = s.details["header"]
    rec = np.memmap(s.path, dtype=record_dtype(h), mode="r", offset=h.data_start, shape=(h.points,))
    cols = [f"f{find_column(h.fields, a)}" for a in ("x", "y", "z")]
    ci = find_column(h.fields, "intensity")
    return rec, cols, f"f{ci}" if ci is not None else None


def _pcd_chunks(s: ScanStream, index: int, chunk_points: int) -> Iterator[Chunk]:
    yield from _record_chunks(*_pcd_records(s), chunk_points)


def _record_chunks(rec: np.ndarray, cols: list[str], icol: str | None, chunk_points: int) -> Iterator[Chunk]:
    for start in range(0, len(rec), chunk_points):
        part = rec[start:start + chunk_points]
        xyz = np.empty((len(part), 3))
        for k, c in enumerate(cols):
            v = part[c]
            xyz[:, k] = v if v.ndim == 1 else v[:, 0]
        raw = None
        if icol is not None:
            v = part[icol]
            raw = np.array(v if v.ndim == 1 else v[:, 0])
        ok = np.isfinite(xyz).all(axis=1)
        if raw is not None and raw.dtype.kind == "f":
            ok &= np.isfinite(raw)
        if not ok.all():
            xyz, raw = xyz[ok], (raw[ok] if raw is not None else None)
        yield Chunk(xyz, raw)


# ------------------------------------------------------------------ anything else: read whole, hand out in chunks
def _whole_scan_chunks(scan, start: int, stop: int | None, chunk_points: int) -> Iterator[Chunk]:
    raw = scan.intensity_raw
    stop = len(scan) if stop is None else min(stop, len(scan))
    for k in range(start, stop, chunk_points):
        e = min(k + chunk_points, stop)
        yield Chunk(scan.xyz_socs[k:e], None if raw is None else raw[k:e])

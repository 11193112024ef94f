"""E57 reading (every scan in the file, with its pose) and writing, through pye57."""
from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pye57
from pye57 import libe57

from common.errors import ScanFormatError
from common.progress import ProgressCallback, report
from lidar.io._common import (
    atomic_output,
    check_readable,
    first_line,
    make_scan,
    pose_from_quaternion,
    quaternion_from_pose,
    quiet_stderr,
    raw_for_writing,
)
from lidar.io.e57_header import check_e57
from lidar.scan import Scan


def _intensity_limits(node) -> tuple[float, float] | None:
    try:
        if not node.isDefined("intensityLimits"):
            return None
        lim = node["intensityLimits"]
        lo, hi = float(lim["intensityMinimum"].value()), float(lim["intensityMaximum"].value())
        return (lo, hi) if hi > lo else None
    except Exception:  # malformed limits: fall back to the data's own range
        return None


def _scan_name(node, index: int) -> str:
    try:
        if node.isDefined("name"):
            return str(node["name"].value())
    except Exception:
        pass
    return f"scan{index}"


_WANTED = ("cartesianX", "cartesianY", "cartesianZ", "cartesianInvalidState", "sphericalRange",
           "sphericalAzimuth", "sphericalElevation", "sphericalInvalidState", "intensity",
           "rowIndex", "columnIndex")


def read_e57(path: str | os.PathLike, *, progress: ProgressCallback | None = None) -> list[Scan]:
    """Read every scan of an E57 file.

    Each scan keeps its points in its own frame (SOCS) with its pose (SOCS ->
    file frame) from the E57 header; spherical coordinates are converted;
    points flagged invalid are dropped. Intensity may be absent (then None).

    Raises
    ------
    ScanFormatError
        Not an E57 file, a checksum error, a scan without points, or no scans.
    """
    p = check_readable(path)
    facts = check_e57(p)  # pages, XML and point counts checked before libE57 allocates anything
    if not facts.scans:
        if facts.images:
            raise ScanFormatError(p, f"the E57 file holds {facts.images} image(s) and no point scans; export the "
                                     "point cloud from the scanner software")
        raise ScanFormatError(p, "the E57 file holds no scans")
    for k, s in enumerate(facts.scans):
        if s.record_count == 0:
            raise ScanFormatError(p, f"scan {k} ({s.name}) holds no points")
    scans: list[Scan] = []
    with opened_e57(p) as e57:
        try:
            count = e57.scan_count
            if count == 0:
                raise ScanFormatError(p, "the E57 file holds no scans")
            for i in range(count):
                scans.append(_read_one(e57, p, i, facts.version))
                report(progress, (i + 1) / count, f"E57 scan {i + 1}/{count}")
        except ScanFormatError:
            raise
        except Exception as exc:
            raise ScanFormatError(p, f"corrupt E57 data ({first_line(exc)})") from exc
    return scans


@contextlib.contextmanager
def opened_e57(p: Path) -> Iterator:
    """pye57's reader of an E57 file (checked by :func:`lidar.io.e57_header.check_e57`), closed after use.

    Raises
    ------
    ScanFormatError
        libE57 cannot open the file.
    """
    try:
        with quiet_stderr():
            e57 = pye57.E57(str(p), mode="r")
    except Exception as exc:
        raise ScanFormatError(p, f"not a readable E57 file ({first_line(exc)})") from exc
    try:
        yield e57
    finally:
        with contextlib.suppress(Exception):
            e57.close()


def acquisition_starts(path: str | os.PathLike) -> list[float | None]:
    """Each scan's ``acquisitionStart`` (GPS seconds, as the file stores it), None where a scan has none.

    Raises
    ------
    ScanFormatError
        Not a readable E57 file.
    """
    p = check_readable(path)
    check_e57(p)
    with opened_e57(p) as e57:
        try:
            return [float(node["acquisitionStart"]["dateTimeValue"].value()) if node.isDefined("acquisitionStart")
                    else None for node in (e57.data3d[k] for k in range(e57.scan_count))]
        except Exception as exc:
            raise ScanFormatError(p, f"corrupt E57 header ({first_line(exc)})") from exc


#: Point fields pye57's buffers do not know, read through libE57 directly: (name, numpy dtype).
_TIME_FIELDS = (("timeStamp", np.float64), ("isTimeStampInvalid", np.int8))


def _read_fields(e57, header, p: Path, i: int) -> dict:
    """The point fields we use of scan ``i``, as arrays (times included when the scan has them)."""
    # Read only what we use: other fields (colour, return counts...) may have value
    # ranges pye57's fixed buffer types cannot hold.
    wanted = [f for f in header.point_fields if f in _WANTED]
    n = header.point_count
    data, buffers = e57.make_buffers(wanted, n)
    for f, dtype in _TIME_FIELDS:
        if f in header.point_fields:
            data[f] = np.empty(n, dtype)
            buffers.append(libe57.SourceDestBuffer(e57.image_file, f, data[f], n, True, True))
    reader = header.points.reader(buffers)
    try:
        got = reader.read()
    finally:
        reader.close()
    if got != n:
        raise ScanFormatError(p, f"truncated: scan {i} declares {n} points, {got} could be read")
    return data


def _times(data: dict) -> np.ndarray | None:
    """(N,) ``timeStamp`` seconds (NaN where flagged invalid), or None when the scan has no usable times."""
    if "timeStamp" not in data:
        return None
    t = np.asarray(data["timeStamp"], dtype=np.float64).copy()
    if "isTimeStampInvalid" in data:
        t[np.asarray(data["isTimeStampInvalid"]) != 0] = np.nan
    return None if not np.any(np.isfinite(t)) else t


def _read_one(e57, p: Path, i: int, version: str) -> Scan:
    with quiet_stderr():
        header = e57.get_header(i)
        node = e57.data3d[i]
        name = _scan_name(node, i)
        if header.point_count == 0:
            raise ScanFormatError(p, f"scan {i} ({name}) holds no points")
        fields = set(header.point_fields)
        data = _read_fields(e57, header, p, i)
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
        raise ScanFormatError(p, f"scan {i} ({name}) has neither cartesian nor spherical coordinates")
    raw = np.asarray(data["intensity"]) if "intensity" in data else None
    times = _times(data)
    grid = None
    if "rowIndex" in data and "columnIndex" in data:
        grid = np.column_stack([data["rowIndex"], data["columnIndex"]]).astype(np.int32)
    if invalid is not None:
        keep = np.asarray(invalid) == 0
        xyz = xyz[keep]
        raw = raw[keep] if raw is not None else None
        grid = grid[keep] if grid is not None else None
        times = times[keep] if times is not None else None
    limits = _intensity_limits(node) if raw is not None else None
    pose = pose_from_quaternion(header.rotation, header.translation)
    return make_scan(
        p, xyz, raw, fmt="E57", limits=limits, pose=pose, name=name, grid_index=grid, time_s=times,
        metadata={"scan_index": i, "fields": sorted(fields), "version": version, "has_time": times is not None},
    )


def write_e57(scans: Scan | list[Scan], path: str | os.PathLike) -> Path:
    """Write one or several scans (each with its pose) to an E57 file.

    A scan with point times (``time_s``) gets a double-precision ``timeStamp`` field holding them as they
    are (seconds) and its ``acquisitionStart`` set to the first; a scan without times is written by
    pye57 exactly as before times were written.
    """
    if isinstance(scans, Scan):
        scans = [scans]
    final = Path(path)
    with atomic_output(final) as tmp:
        with quiet_stderr():
            e57 = pye57.E57(str(tmp), mode="w")
            try:
                for scan in scans:
                    data = {
                        "cartesianX": scan.xyz_socs[:, 0].copy(),
                        "cartesianY": scan.xyz_socs[:, 1].copy(),
                        "cartesianZ": scan.xyz_socs[:, 2].copy(),
                    }
                    if scan.intensity is not None:
                        data["intensity"] = raw_for_writing(scan).astype(np.float64)
                    q, t = quaternion_from_pose(scan.pose) if scan.pose is not None else (None, None)
                    if scan.time_s is None:
                        kwargs: dict[str, object] = {"name": scan.name or "scan"}
                        if q is not None:
                            kwargs.update(rotation=q, translation=t)
                        e57.write_scan_raw(data, **kwargs)
                    else:
                        _write_timed_scan(e57, data, scan.time_s, name=scan.name or "scan", rotation=q,
                                          translation=t)
            finally:
                e57.close()
    return final


def _write_timed_scan(e57, data: dict, time_s: np.ndarray, *, name: str, rotation: np.ndarray | None,
                      translation: np.ndarray | None) -> None:
    """One scan with a ``timeStamp`` field, through libE57 (pye57's writer knows no times).

    Coordinates and intensity are stored as pye57 stores them (single precision), the times in double.
    """
    imf = e57.image_file
    node = libe57.StructureNode(imf)
    node.set("guid", libe57.StringNode(imf, f"{{{uuid.uuid4()}}}"))
    node.set("name", libe57.StringNode(imf, name))
    node.set("description", libe57.StringNode(imf, "BridgeSurvey"))
    xyz = np.column_stack([data["cartesianX"], data["cartesianY"], data["cartesianZ"]])
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    data["timeStamp"] = np.ascontiguousarray(time_s, dtype=np.float64)
    if "intensity" in data:
        limits = libe57.StructureNode(imf)
        limits.set("intensityMinimum", libe57.FloatNode(imf, float(data["intensity"].min())))
        limits.set("intensityMaximum", libe57.FloatNode(imf, float(data["intensity"].max())))
        node.set("intensityLimits", limits)
    if rotation is not None and translation is not None:
        pose = libe57.StructureNode(imf)
        rot = libe57.StructureNode(imf)
        for k, v in zip("wxyz", rotation, strict=False):
            rot.set(k, libe57.FloatNode(imf, float(v)))
        tr = libe57.StructureNode(imf)
        for k, v in zip("xyz", translation, strict=False):
            tr.set(k, libe57.FloatNode(imf, float(v)))
        pose.set("rotation", rot)
        pose.set("translation", tr)
        node.set("pose", pose)
    start = libe57.StructureNode(imf)
    start.set("dateTimeValue", libe57.FloatNode(imf, float(np.nanmin(time_s))))
    start.set("isAtomicClockReferenced", libe57.IntegerNode(imf, 0))
    node.set("acquisitionStart", start)
    proto = libe57.StructureNode(imf)
    for axis, f in enumerate(("cartesianX", "cartesianY", "cartesianZ")):
        proto.set(f, libe57.FloatNode(imf, float((lo[axis] + hi[axis]) / 2), libe57.E57_SINGLE, float(lo[axis]),
                                      float(hi[axis])))
    if "intensity" in data:
        i_lo, i_hi = float(data["intensity"].min()), float(data["intensity"].max())
        proto.set("intensity", libe57.FloatNode(imf, i_lo, libe57.E57_SINGLE, i_lo, i_hi))
    t_lo, t_hi = float(np.nanmin(time_s)), float(np.nanmax(time_s))
    proto.set("timeStamp", libe57.FloatNode(imf, t_lo, libe57.E57_DOUBLE, t_lo, t_hi))
    points = libe57.CompressedVectorNode(imf, proto, libe57.VectorNode(imf, True))
    node.set("points", points)
    e57.data3d.append(node)
    buffers = libe57.VectorSourceDestBuffer()
    arrays = {f: np.ascontiguousarray(data[f], dtype=np.float64) for f in data}
    n = xyz.shape[0]
    for f, a in arrays.items():
        buffers.append(libe57.SourceDestBuffer(imf, f, a, n, True, True))
    writer = points.writer(buffers)
    writer.write(n)
    writer.close()

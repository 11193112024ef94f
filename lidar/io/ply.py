"""PLY point clouds (ASCII and binary) with intensity, through plyfile."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from lidar.errors import ScanFormatError
from lidar.io._common import atomic_output, first_line, check_readable, make_scan, raw_for_writing
from lidar.scan import Scan

#: Property names other tools use for intensity, in order of preference.
INTENSITY_NAMES = ("intensity", "scalar_intensity", "scalar_Intensity", "Intensity", "reflectance",
                   "scalar_Reflectance", "scalar_reflectance", "remission")


def read_ply(path: str | os.PathLike) -> Scan:
    """Read the ``vertex`` element of a PLY file (x, y, z and an intensity-like property)."""
    from plyfile import PlyData

    p = check_readable(path)
    try:
        ply = PlyData.read(str(p))
        vertex = ply["vertex"]
        data = vertex.data
        names = data.dtype.names or ()
        if not {"x", "y", "z"} <= set(names):
            raise ScanFormatError(p, "the PLY vertex element has no x, y, z properties")
        xyz = np.column_stack([data["x"], data["y"], data["z"]]).astype(np.float64)
    except ScanFormatError:
        raise
    except KeyError as exc:
        raise ScanFormatError(p, "the PLY file has no 'vertex' element") from exc
    except Exception as exc:  # plyfile raises many types for malformed input
        raise ScanFormatError(p, f"not a readable PLY file ({first_line(exc)})") from exc
    raw = None
    for name in INTENSITY_NAMES:
        if name in names:
            raw = np.asarray(data[name])
            break
    return make_scan(p, xyz, raw, fmt="PLY", metadata={"ply_format": ply.text and "ascii" or "binary"})


def write_ply(scan: Scan, path: str | os.PathLike, *, binary: bool = True) -> Path:
    """Write x, y, z (float64) and the raw intensity as a PLY vertex element."""
    from plyfile import PlyData, PlyElement

    final = Path(path)
    raw = raw_for_writing(scan)
    rec = np.empty(len(scan), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("intensity", raw.dtype.str)])
    rec["x"], rec["y"], rec["z"] = scan.xyz_socs.T
    rec["intensity"] = raw
    with atomic_output(final) as tmp:
        PlyData([PlyElement.describe(rec, "vertex")], text=not binary).write(str(tmp))
    return final

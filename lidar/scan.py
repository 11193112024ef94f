"""The one in-memory scan type.

A :class:`Scan` holds the points of one scanner set-up in the scanner's own
coordinate system (SOCS), float64 metres, with intensity normalised to [0, 1]
and the raw values kept beside it.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from common.errors import InputError


def normalise_intensity(raw: np.ndarray, limits: tuple[float, float] | None = None) -> np.ndarray:
    """Map raw intensities linearly onto [0, 1].

    Parameters
    ----------
    raw : (N,) array
        Raw intensity values in the file's own units.
    limits : (lo, hi), optional
        The value range the file declares (e.g. E57 ``intensityLimits``). By
        default the file's own minimum and maximum are used.

    Returns
    -------
    (N,) float32 array in [0, 1]. A constant-intensity file maps to zeros.
    """
    raw = np.asarray(raw)
    if raw.size == 0:
        return np.zeros(0, np.float32)
    if limits is None:
        lo, hi = float(np.min(raw)), float(np.max(raw))
    else:
        lo, hi = float(limits[0]), float(limits[1])
    if not np.isfinite(lo) or not np.isfinite(hi) or hi <= lo:
        return np.zeros(raw.shape, np.float32)
    if raw.dtype in (np.uint8, np.uint16):  # one table look-up pass instead of four arithmetic passes
        lut = np.clip((np.arange(1 << (8 * raw.dtype.itemsize), dtype=np.float64) - lo) / (hi - lo), 0.0, 1.0)
        return lut.astype(np.float32)[raw]
    out = raw.astype(np.float32)
    out -= np.float32(lo)
    out *= np.float32(1.0 / (hi - lo))
    np.clip(out, 0.0, 1.0, out=out)
    return out


@dataclass(frozen=True, eq=False)
class Scan:
    """Points of one scanner set-up.

    Attributes
    ----------
    xyz_socs : (N, 3) float64 array
        Point coordinates in the scanner's own frame, metres.
    intensity : (N,) float32 array or None
        Intensity normalised per file to [0, 1]; None when the file has none.
    intensity_raw : (N,) array or None
        The intensity values exactly as stored in the file.
    pose : (4, 4) float64 array or None
        Homogeneous transform from SOCS into the file's project/world frame.
    source : str
        Path of the file the points came from ("" for synthetic scans).
    name : str
        Scan name inside the file (E57/PTX scans), else the file stem.
    grid_index : (N, 2) int32 array or None
        (row, col) of each point in the scanner's angular grid, if the file has one.
    metadata : mapping
        Format details (format, version, point format, scales, counts of dropped points...).
    time_s : (N,) float64 array or None
        Time of each point, seconds (LAS ``gps_time``, E57 ``timeStamp``); only differences within one
        visit mean anything. None when the file has no times.
    """

    xyz_socs: np.ndarray
    intensity: np.ndarray | None = None
    intensity_raw: np.ndarray | None = None
    pose: np.ndarray | None = None
    source: str = ""
    name: str = ""
    grid_index: np.ndarray | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)
    time_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        xyz = self.xyz_socs
        if not isinstance(xyz, np.ndarray) or xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"scan {self.name or self.source!r}: xyz_socs must be an (N, 3) array, got shape {np.shape(xyz)}")
        if xyz.dtype != np.float64:
            raise InputError(f"scan {self.name or self.source!r}: xyz_socs must be float64 metres, got {xyz.dtype}")
        n = xyz.shape[0]
        for attr in ("intensity", "intensity_raw"):
            a = getattr(self, attr)
            if a is not None and (a.ndim != 1 or a.shape[0] != n):
                raise InputError(f"scan {self.name or self.source!r}: {attr} must have shape ({n},), got {a.shape}")
        if self.intensity is not None and self.intensity.dtype != np.float32:
            raise InputError(f"scan {self.name or self.source!r}: intensity must be float32 in [0, 1]")
        if self.pose is not None:
            pose = np.asarray(self.pose, dtype=np.float64)
            if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
                raise InputError(f"scan {self.name or self.source!r}: pose must be a finite 4x4 matrix")
            object.__setattr__(self, "pose", pose)
        if self.time_s is not None:
            ts = np.asarray(self.time_s, dtype=np.float64)
            if ts.shape != (n,):
                raise InputError(f"scan {self.name or self.source!r}: time_s must have shape ({n},), got {ts.shape}")
            object.__setattr__(self, "time_s", ts)
        if self.grid_index is not None and self.grid_index.shape != (n, 2):
            raise InputError(f"scan {self.name or self.source!r}: grid_index must have shape ({n}, 2)")
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))

    def __len__(self) -> int:
        return int(self.xyz_socs.shape[0])

    def __reduce__(self):  # the read-only metadata proxy does not pickle; rebuild from a plain dict
        return (Scan, (self.xyz_socs, self.intensity, self.intensity_raw, self.pose, self.source, self.name,
                       self.grid_index, dict(self.metadata), self.time_s))

    @property
    def has_intensity(self) -> bool:
        return self.intensity is not None

    def xyz_world(self) -> np.ndarray:
        """(N, 3) float64 coordinates in the pose's frame (SOCS if there is no pose)."""
        if self.pose is None:
            return self.xyz_socs.copy()
        return self.xyz_socs @ self.pose[:3, :3].T + self.pose[:3, 3]

    def subset(self, index: np.ndarray) -> Scan:
        """A new scan holding the points selected by a boolean mask or index array."""

        def take(a):
            return None if a is None else a[index]

        return Scan(
            xyz_socs=np.ascontiguousarray(self.xyz_socs[index]),
            intensity=take(self.intensity),
            intensity_raw=take(self.intensity_raw),
            pose=self.pose,
            source=self.source,
            name=self.name,
            grid_index=take(self.grid_index),
            metadata=self.metadata,
            time_s=take(self.time_s),
        )

    @classmethod
    def concatenate(cls, scans: list[Scan], *, name: str = "") -> Scan:
        """Join scans of one set-up (same SOCS) into one, e.g. several fine-scan files.

        Point times are kept when every scan has them (else the result has none).
        """
        if not scans:
            raise InputError("no scans to concatenate")
        has_i = all(s.intensity is not None for s in scans)
        raw = None
        if all(s.intensity_raw is not None for s in scans):
            raw = np.concatenate([np.asarray(s.intensity_raw, dtype=np.float64) for s in scans])
        return cls(
            xyz_socs=np.concatenate([s.xyz_socs for s in scans]),
            intensity=np.concatenate([s.intensity for s in scans]) if has_i else None,
            intensity_raw=raw,
            pose=scans[0].pose,
            source=";".join(s.source for s in scans),
            name=name or scans[0].name,
            metadata={"parts": [s.name or s.source for s in scans]},
            time_s=np.concatenate([s.time_s for s in scans]) if all(s.time_s is not None for s in scans) else None,
        )

"""What a scan file holds, for a surveyor deciding whether to use it (``bridgesurvey info``).

:func:`describe_file` reads a file with the same bounded readers as every
other command and summarises each scan in it: points, bounds, pose, the
intensity convention recognised, the angular step estimated from the points
(and what it means as point spacing at 10 m), and the problems found.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from lidar.io.poses import FAR_FROM_SCANNER_M, carry_to_scanner, in_project_frame  # noqa: F401  (the test, named here too)
from lidar.scan import Scan

#: Points used for the step and duplicate estimates (a seeded sample of larger scans).
SAMPLE_POINTS = 200_000
#: Coordinates coarser than this lose what a target centroid needs.
COARSE_SCALE_M = 0.001


@dataclass(frozen=True)
class ScanInfo:
    """Summary of one scan (one set-up) of a file. Lengths in metres, angles in degrees."""

    name: str
    points: int
    bounds_min: tuple[float, ...]
    bounds_max: tuple[float, ...]
    pose: Optional[list[list[float]]]
    intensity_convention: str
    intensity_raw_range: Optional[tuple[float, float]]
    angular_step_deg: Optional[float]
    spacing_at_10m_mm: Optional[float]
    range_m: tuple[float, float]
    duplicate_points: int
    problems: tuple[str, ...] = ()
    frame: str = "scanner"  # "scanner" (SOCS), or "project" (a project or national frame: see lidar.io.poses)


@dataclass(frozen=True)
class FileInfo:
    """Summary of a scan file."""

    path: str
    format: str
    version: str
    size_bytes: int
    scans: tuple[ScanInfo, ...]
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def estimate_angular_step_deg(xyz_socs: np.ndarray, *, seed: int = 0) -> Optional[float]:
    """Typical angular spacing of neighbouring points seen from the scanner (degrees).

    Uses the median nearest-neighbour distance on the unit sphere of a sample
    of at most :data:`SAMPLE_POINTS` points, corrected for the sampling
    (a subsample of a regular grid is sparser by sqrt(N / n)).

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        Points in the scanner's own frame, metres.

    Returns
    -------
    float or None
        None for fewer than 10 points.
    """
    from scipy.spatial import cKDTree

    n = xyz_socs.shape[0]
    if n < 10:
        return None
    rng = np.random.default_rng(seed)
    sample = xyz_socs if n <= SAMPLE_POINTS else xyz_socs[rng.choice(n, SAMPLE_POINTS, replace=False)]
    r = np.linalg.norm(sample, axis=1)
    unit = sample[r > 0] / r[r > 0, None]
    if unit.shape[0] < 10:
        return None
    d, _ = cKDTree(unit).query(unit, k=2)
    nn = d[:, 1]
    nn = nn[nn > 0]
    if nn.size == 0:
        return None
    step = float(np.degrees(np.median(nn))) * np.sqrt(unit.shape[0] / n)
    return step


def _duplicates(xyz: np.ndarray, seed: int = 0) -> int:
    n = xyz.shape[0]
    if n <= SAMPLE_POINTS * 5:
        return int(n - np.unique(xyz, axis=0).shape[0])
    rng = np.random.default_rng(seed)
    idx = rng.choice(n, SAMPLE_POINTS * 5, replace=False)
    return int(round((idx.size - np.unique(xyz[idx], axis=0).shape[0]) * n / idx.size))


def scan_info(scan: Scan) -> ScanInfo:
    """Summarise one scan."""
    xyz = scan.xyz_socs
    meta = dict(scan.metadata)
    problems = []
    if meta.get("dropped_nonfinite_points"):
        problems.append(f"{meta['dropped_nonfinite_points']} NaN/infinite points dropped")
    for k, s in enumerate(meta.get("scales", ()) or ()):
        if abs(s) > COARSE_SCALE_M:
            problems.append(f"{'xyz'[k]} coordinates are quantised to {abs(s) * 1000:g} mm (coarser than 1 mm)")
    dup = _duplicates(xyz)
    if dup:
        problems.append(f"{dup} duplicate points")
    if scan.intensity is None:
        problems.append("no intensity: reflectors cannot be detected in this file")
    raw_range = None
    if scan.intensity_raw is not None:
        raw_range = (float(np.min(scan.intensity_raw)), float(np.max(scan.intensity_raw)))
        if raw_range[0] == raw_range[1]:
            problems.append("intensity is constant: reflectors cannot be detected in this file")
    rng_m = np.linalg.norm(xyz, axis=1)
    step = None
    frame = "project" if in_project_frame(xyz) else "scanner"
    if frame == "project":
        own = scan.pose is not None and not in_project_frame(carry_to_scanner(scan, scan.pose).xyz_socs)
        problems.append(f"every point is more than {rng_m.min() / 1000:.0f} km from the origin: the coordinates are "
                        "in a project frame, not the scanner's own (SOCS); angles and steps are not meaningful"
                        + ("; its own pose carries it into the scanner's frame at import" if own else
                           "; importing it needs its scanner pose (--pose FILE or --origin X,Y,Z)"))
    else:
        step = estimate_angular_step_deg(xyz)
    return ScanInfo(
        name=scan.name, points=len(scan),
        bounds_min=tuple(float(v) for v in xyz.min(axis=0)), bounds_max=tuple(float(v) for v in xyz.max(axis=0)),
        pose=scan.pose.tolist() if scan.pose is not None else None,
        intensity_convention=str(meta.get("intensity_convention", "none")),
        intensity_raw_range=raw_range,
        angular_step_deg=step, spacing_at_10m_mm=None if step is None else float(np.radians(step) * 10.0 * 1000.0),
        range_m=(float(rng_m.min()), float(rng_m.max())), duplicate_points=dup, problems=tuple(problems), frame=frame,
    )


def describe_file(path: str | os.PathLike) -> FileInfo:
    """Read a scan file (any supported format) and summarise it.

    Raises
    ------
    ScanFormatError
        The file cannot be read; the message names the file and the problem.
    """
    from lidar.io import read_scans

    p = Path(path)
    scans = read_scans(p)
    meta = dict(scans[0].metadata)
    version = str(meta.get("version", ""))
    details = {k: v for k, v in meta.items() if k in ("point_format", "scales", "offsets", "compressed", "pcd_data",
                                                        "ply_format", "fields", "properties", "columns")}
    return FileInfo(path=str(p), format=str(meta.get("format", "")), version=version,
                    size_bytes=p.stat().st_size, scans=tuple(scan_info(s) for s in scans), details=details)

"""What a scan file holds, for a surveyor deciding whether to use it (``bridgesurvey info``).

:func:`describe_file` works at header speed: for LAS/LAZ, E57, PLY and PCD it reports what the header knows
(format, version, scans, point counts, bounds, scales, pose, point format) with the same checks as every
reader, and the angular steps from a few runs of consecutive points. With ``stats=True`` it reads every point
in chunks (memory bounded by the chunk, whatever the file's size) for the bounds, ranges, the intensity range
and its vendor convention, duplicates, NaN points, and the angular steps from whole angular patches of the
scan. PTX, PTS and XYZ files have no header that tells the points: they are always read whole.
"""
from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from common.arrays import unique_sorted
from common.progress import ProgressCallback, report
from lidar.io.angular_step import AngularSteps, PatchSampler, angles_deg, steps_along_lines, steps_from_neighbours
from lidar.io.intensity import detect_convention
from lidar.io.poses import FAR_FROM_SCANNER_M, in_project_frame, to_scanner_frame
from lidar.io.stream import CHUNK_POINTS, Chunk, ScanStream, StreamScan, open_stream

#: Coordinates coarser than this lose what a target centroid needs.
COARSE_SCALE_M = 0.001
#: Points whose duplicates are counted exactly (a hash-chosen share of larger scans, scaled up).
DUPLICATE_SAMPLE = 2_000_000


@dataclass(frozen=True)
class ScanInfo:
    """Summary of one scan (one set-up) of a file. Lengths in metres, angles in degrees.

    Fields the header does not know are None until the points are read (``stats``).
    """

    name: str
    points: int
    bounds_min: tuple[float, ...] | None
    bounds_max: tuple[float, ...] | None
    pose: list[list[float]] | None
    intensity_convention: str | None
    intensity_raw_range: tuple[float, float] | None
    angular_step_deg: float | None
    theta_step_deg: float | None
    phi_step_deg: float | None
    step_from: str
    spacing_at_10m_mm: float | None
    range_m: tuple[float, float] | None
    duplicate_points: int | None
    problems: tuple[str, ...] = ()
    frame: str = "scanner"  # "scanner" (SOCS), or "project" (a project or national frame: see lidar.io.poses)


@dataclass(frozen=True)
class FileInfo:
    """Summary of a scan file; ``stats`` tells whether every point was read."""

    path: str
    format: str
    version: str
    size_bytes: int
    scans: tuple[ScanInfo, ...]
    stats: bool
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


def estimate_angular_steps(xyz_socs: np.ndarray) -> AngularSteps:
    """Both angular steps of points holding whole neighbourhoods (a scan, or consecutive points of one).

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        Points in the scanner's own frame, metres, in file order.

    Returns
    -------
    AngularSteps
        From the file order when it is a scan order, else from each point's angular neighbours.
    """
    theta, phi = angles_deg(xyz_socs)
    lines = steps_along_lines(theta, phi)
    if lines.regular:
        return lines
    return steps_from_neighbours(theta, phi)


class _Stats:
    """Accumulates one scan's statistics over its chunks, in bounded memory."""

    def __init__(self, declared_points: int):
        self.n = 0
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)
        self.r = [np.inf, -np.inf]
        self.i_lo, self.i_hi, self.i_integral = np.inf, -np.inf, True
        self.i_dtype: np.dtype | None = None
        self.patches = PatchSampler()
        self.dup_every = max(1, declared_points // DUPLICATE_SAMPLE)
        self.dup_hashes: list[np.ndarray] = []
        self.first: np.ndarray | None = None  # the first chunk's first points (a project-frame scan's pose check)

    def sample_xyz(self) -> np.ndarray:
        return self.first if self.first is not None else np.empty((0, 3))

    def add(self, c: Chunk) -> None:
        xyz = c.xyz
        if len(xyz) == 0:
            return
        if self.first is None:
            self.first = np.array(xyz[:10_000], dtype=np.float64)
        self.n += len(xyz)
        for k in range(3):  # column by column: a reduction over the rows of an (N, 3) array is 3x slower
            self.lo[k], self.hi[k] = min(self.lo[k], xyz[:, k].min()), max(self.hi[k], xyz[:, k].max())
        rng = np.sqrt(np.einsum("ij,ij->i", xyz, xyz))
        self.r = [min(self.r[0], float(rng.min())), max(self.r[1], float(rng.max()))]
        if c.raw is not None and len(c.raw):
            self.i_dtype = c.raw.dtype
            self.i_lo, self.i_hi = min(self.i_lo, float(c.raw.min())), max(self.i_hi, float(c.raw.max()))
            if self.i_integral and c.raw.dtype.kind == "f":
                self.i_integral = bool(np.all(c.raw == np.round(c.raw)))
        if rng.min() < FAR_FROM_SCANNER_M:  # cells from cheap float32 angles, the kept points' in float64
            keep = self.patches.wanted(*angles_deg(xyz, np.float32))
            if keep.any():
                self.patches.add(*angles_deg(xyz[keep]))
        h = _point_hash(xyz)
        self.dup_hashes.append(h[h % np.uint64(self.dup_every) == 0])

    def duplicates(self) -> int:
        h = np.concatenate(self.dup_hashes) if self.dup_hashes else np.zeros(0, np.uint64)
        return int(round((h.size - unique_sorted(h).size) * self.dup_every))

    def convention(self) -> tuple[str | None, tuple[float, float] | None]:
        if self.i_dtype is None:
            return None, None
        sample = np.array([self.i_lo, self.i_hi] if self.i_integral else
                          [self.i_lo, self.i_hi, self.i_lo + (self.i_hi - self.i_lo) * 0.5 + 1e-3]).astype(self.i_dtype)
        name, _ = detect_convention(sample)
        return name, (self.i_lo, self.i_hi)


def _point_hash(xyz: np.ndarray) -> np.ndarray:
    """64-bit hash of each point's exact coordinates (equal points, equal hashes)."""
    b = np.ascontiguousarray(xyz, dtype=np.float64).view(np.uint64)
    h = b[:, 0] * np.uint64(0x9E3779B97F4A7C15)
    h ^= b[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F) + (h >> np.uint64(31))
    h ^= b[:, 2] * np.uint64(0x165667B19E3779F9) + (h >> np.uint64(27))
    h ^= h >> np.uint64(33)
    return h


def _step_fields(steps: AngularSteps | None, source: str) -> dict:
    if steps is None or not steps.regular:
        return {"angular_step_deg": None, "theta_step_deg": None, "phi_step_deg": None, "spacing_at_10m_mm": None,
                "step_from": source}
    step = float(steps.step_deg)  # type: ignore[arg-type]
    return {"angular_step_deg": step, "theta_step_deg": float(steps.theta_deg),  # type: ignore[arg-type]
            "phi_step_deg": float(steps.phi_deg), "spacing_at_10m_mm": float(np.radians(step) * 10.0 * 1000.0),  # type: ignore[arg-type]
            "step_from": f"{source} ({steps.method}, {steps.regular_share:.0%} of the neighbours one step apart)"}


def _scale_problems(details: dict) -> list[str]:
    return [f"{'xyz'[k]} coordinates are quantised to {abs(s) * 1000:g} mm (coarser than 1 mm)"
            for k, s in enumerate(details.get("scales", ()) or ()) if abs(s) > COARSE_SCALE_M]


def _not_regular(steps: AngularSteps | None) -> list[str]:
    if steps is None or steps.points < 20 or steps.regular:
        return []
    return ["the points are not on a regular angular grid seen from the origin (a registered, merged or "
            "resampled cloud, or not a scanner's own frame): no angular step"]


def _header_scan(stream: ScanStream, k: int, s: StreamScan) -> ScanInfo:
    """What the header knows of scan ``k``, with the steps from a few runs of consecutive points."""
    problems = _scale_problems(stream.details)
    blocks = stream.sample_blocks(k)
    xyz = np.vstack([b.xyz for b in blocks]) if blocks else np.empty((0, 3))
    steps, source = None, "not estimated: --stats reads every point"
    if len(xyz):
        if np.linalg.norm(xyz, axis=1).min() > FAR_FROM_SCANNER_M:
            problems.append(_far_problem(float(np.linalg.norm(xyz, axis=1).min()), xyz, s.pose))
        else:
            per_block = [estimate_angular_steps(b.xyz) for b in blocks if len(b.xyz) >= 20]
            good = [b for b in per_block if b.regular]
            steps = good[0] if good else (per_block[0] if per_block else None)
            source = f"{sum(len(b.xyz) for b in blocks):,} consecutive points sampled in the file"
            if steps is not None and not steps.regular:
                source += "; not in scan order: --stats looks at whole angular patches"
                steps = None
    if not s.has_intensity:
        problems.append("no intensity: reflectors cannot be detected in this file")
    bounds = s.bounds
    conv = "declared limits" if s.intensity_limits else None
    far = bool(len(xyz)) and np.linalg.norm(xyz, axis=1).min() > FAR_FROM_SCANNER_M
    return ScanInfo(name=s.name, points=s.points, bounds_min=bounds[0] if bounds else None,
                    bounds_max=bounds[1] if bounds else None, pose=None if s.pose is None else s.pose.tolist(),
                    intensity_convention=conv, intensity_raw_range=s.intensity_limits, range_m=None,
                    duplicate_points=None, problems=tuple(problems), frame="project" if far else "scanner",
                    **_step_fields(steps, source))


def _far_problem(r_min: float, xyz: np.ndarray, pose: np.ndarray | None) -> str:
    """Why a project-frame scan's angles mean nothing, and what its import needs (a pose, unless it has its own)."""
    own = pose is not None and len(xyz) > 0 and not in_project_frame(to_scanner_frame(xyz[:100_000], pose))
    return (f"every point is more than {r_min / 1000:.0f} km from the origin: the coordinates are in a project "
            "frame, not the scanner's own (SOCS); angles and steps are not meaningful"
            + ("; its own pose carries it into the scanner's frame at import" if own else
               "; importing it needs its scanner pose (--pose FILE or --origin X,Y,Z)"))


def _full_scan(stream: ScanStream, k: int, s: StreamScan, progress: ProgressCallback | None) -> ScanInfo:
    """Every point of scan ``k`` read in chunks."""
    acc = _Stats(s.points)
    for c in stream.chunks(k, CHUNK_POINTS):
        acc.add(c)
        report(progress, min(acc.n / max(s.points, 1), 1.0), f"reading {s.name}")
    problems = _scale_problems(stream.details)
    dropped = s.points - acc.n
    if stream.loaded is not None:  # read whole: the reader counted what it dropped
        dropped = int(dict(stream.loaded[k].metadata).get("dropped_nonfinite_points", 0))
    if dropped > 0 and stream.kind != "e57":
        problems.append(f"{dropped} NaN/infinite points dropped")
    elif dropped > 0:
        problems.append(f"{dropped} points flagged invalid in the file")
    if acc.n == 0:
        problems.append("holds no valid points")
    dup = acc.duplicates()
    if dup:
        problems.append(f"{dup} duplicate points" + (" (estimated from a share of the points)" if acc.dup_every > 1
                                                     else ""))
    conv, raw_range = acc.convention()
    if s.intensity_limits:
        conv, raw_range = "declared limits", s.intensity_limits
    if not s.has_intensity or conv is None:
        problems.append("no intensity: reflectors cannot be detected in this file")
    elif raw_range is not None and raw_range[0] == raw_range[1]:
        problems.append("intensity is constant: reflectors cannot be detected in this file")
    steps = None
    far = bool(acc.n) and acc.r[0] > FAR_FROM_SCANNER_M
    if far:
        problems.append(_far_problem(acc.r[0], acc.sample_xyz(), s.pose))
    elif acc.n:
        steps = acc.patches.steps()
        problems += _not_regular(steps)
    ok = acc.n > 0
    return ScanInfo(name=s.name, points=acc.n, bounds_min=tuple(float(v) for v in acc.lo) if ok else None,
                    bounds_max=tuple(float(v) for v in acc.hi) if ok else None,
                    pose=None if s.pose is None else s.pose.tolist(), intensity_convention=conv,
                    intensity_raw_range=raw_range, range_m=(float(acc.r[0]), float(acc.r[1])) if ok else None,
                    duplicate_points=dup, problems=tuple(problems), frame="project" if far else "scanner",
                    **_step_fields(steps, f"every point ({acc.n:,})"))


def describe_file(path: str | os.PathLike, *, stats: bool = False,
                  progress: ProgressCallback | None = None) -> FileInfo:
    """Describe a scan file (any supported format): at header speed, or reading every point (``stats``).

    Parameters
    ----------
    path : path-like
    stats : bool, keyword-only
        Read every point in chunks (bounded memory) for bounds, ranges, intensity, duplicates and the
        angular steps from whole angular patches. Default False: what the header knows, and the steps from
        a few runs of consecutive points. Files without a point-describing header (PTX, PTS, XYZ) are
        read whole either way.
    progress : callable, optional

    Raises
    ------
    ScanFormatError
        The file cannot be read; the message names the file and the problem.
    """
    p = Path(path)
    stream = open_stream(p)
    full = stats or stream.loaded is not None
    scans = tuple(_full_scan(stream, k, s, progress) if full else _header_scan(stream, k, s)
                  for k, s in enumerate(stream.scans))
    d = stream.details
    details = {k: v for k, v in d.items() if k in ("point_format", "record_length", "scales", "offsets",
                                                   "compressed", "pcd_data", "ply_format", "fields",
                                                   "properties", "dimensions", "vlrs", "evlrs", "images")}
    return FileInfo(path=str(p), format=str(d.get("format", "")), version=str(d.get("version", "")),
                    size_bytes=p.stat().st_size, scans=scans, stats=full, details=details)

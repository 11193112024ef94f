"""Reflectance maps: a coarse scan binned on a (theta, phi) grid.

Each cell holds the maximum and mean normalised intensity, the mean range and
the number of points. The azimuth origin of the grid is placed in the largest
empty azimuth gap of the scan, so no target is cut in two by the 0/360 seam;
a scan covering the full circle is marked ``full_circle`` and its first and
last columns are neighbours.
"""
from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from common.progress import ProgressCallback, report
from common.validation import require_points
from lidar.angles import ATAN_DEG32, direction_from_angles, spherical32, wrap_phi
from lidar.io import read_scan, sniff_format
from lidar.io.las import LasFile, LasRecords, open_las
from lidar.native import coarse_map_library

#: Points per chunk: small enough that a chunk's float32 temporaries stay in the caches.
CHUNK = 262_144
#: Chunks read and binned (on two threads) ahead of the last one added to the map; the LAS records of a
#: batch of this many chunks share one mapping.
BATCH = 4
#: The automatic cell size keeps maps below this many cells: a few cells across a target are enough
#: to find it, and detection time and memory grow with the cell count.
MAX_AUTO_CELLS = 4_000_000


@dataclass(frozen=True, eq=False)
class ReflectanceMap:
    """Intensity and range of a scan on a regular (theta, phi) grid.

    Attributes
    ----------
    theta0_deg : float
        Zenith angle of the upper edge of row 0; rows go down (theta increases).
    phi0_deg : float
        Azimuth of the left edge of column 0 (may be negative across the seam).
    step_deg : float
        Cell size in both angles, degrees.
    max_intensity, mean_intensity : (H, W) float32 arrays, NaN where empty
    range_m : (H, W) float32 array, mean range per cell, NaN where empty
    count : (H, W) int32 array
    full_circle : bool
        The scan covers all azimuths (column 0 follows column W-1).
    n_points : int
    """

    theta0_deg: float
    phi0_deg: float
    step_deg: float
    max_intensity: np.ndarray
    mean_intensity: np.ndarray
    range_m: np.ndarray
    count: np.ndarray
    full_circle: bool
    n_points: int

    @property
    def shape(self) -> tuple[int, int]:
        return self.count.shape

    def cell_angles(self, row: ArrayLike, col: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(theta, phi in [0, 360)) of (fractional) cell indices, at cell centres for integers."""
        theta = self.theta0_deg + (np.asarray(row, dtype=np.float64) + 0.5) * self.step_deg
        phi = wrap_phi(self.phi0_deg + (np.asarray(col, dtype=np.float64) + 0.5) * self.step_deg)
        return theta, phi

    def cells_of(self, theta_deg: ArrayLike, phi_deg: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Fractional (row, col) of directions (cell centres at integers)."""
        row = (np.asarray(theta_deg, dtype=np.float64) - self.theta0_deg) / self.step_deg - 0.5
        col = np.mod(np.asarray(phi_deg, dtype=np.float64) - self.phi0_deg, 360.0) / self.step_deg - 0.5
        return row, col

    @property
    def extent_deg(self) -> tuple[float, float, float, float]:
        """(phi_min, phi_max, theta_max, theta_min) for image display."""
        h, w = self.shape
        return (self.phi0_deg, self.phi0_deg + w * self.step_deg, self.theta0_deg + h * self.step_deg,
                self.theta0_deg)

    def xyz_of(self, theta_deg: ArrayLike, phi_deg: ArrayLike, range_m: ArrayLike) -> np.ndarray:
        return direction_from_angles(theta_deg, phi_deg) * np.asarray(range_m, dtype=np.float64)[..., None]


def _angles32(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(theta, phi in [0, 360], range) in float32 of (N, 3) points; a phi of 360.0 is wrapped by the binning."""
    return spherical32(*(xyz[:, k].astype(np.float32) for k in range(3)))


def occupied_area_deg2(theta_deg: np.ndarray, phi_deg: np.ndarray) -> float:
    """Area (square degrees of the angle grid) of the directions a scan covers, in 0.5-degree cells."""
    return _Survey.of_angles(theta_deg, phi_deg).area_deg2


@dataclass
class _Survey:
    """What a sample of a scan's directions tells the map before binning.

    A 0.1-degree histogram of the azimuth (where the coverage starts and how wide it is), which cells of a
    0.5-degree grid of the sphere hold a point (the occupied area, hence the step) and the range of the
    zenith angle (the map's rows). Surveys of parts of a scan add up to the survey of the whole.
    """

    azimuth_hist: np.ndarray  # (3600,) int64
    occupied: np.ndarray  # (360 * 720,) uint8, 0.5-degree cells row by row (zenith rows, azimuth columns)
    theta_span: np.ndarray  # (2,) float32: smallest and largest zenith angle (inf, -inf when empty)

    @classmethod
    def empty(cls) -> _Survey:
        return cls(np.zeros(3600, np.int64), np.zeros(360 * 720, np.uint8), np.array([np.inf, -np.inf], np.float32))

    @classmethod
    def of_angles(cls, theta_deg: np.ndarray, phi_deg: np.ndarray) -> _Survey:
        """The survey of float32 angles in degrees (phi in [0, 360])."""
        theta_deg, phi_deg = np.asarray(theta_deg, np.float32), np.asarray(phi_deg, np.float32)
        hist = np.bincount(np.clip((phi_deg * 10).astype(np.int32), 0, 3599), minlength=3600)
        rows = np.clip((theta_deg / 0.5).astype(np.int32), 0, 359)
        cols = np.clip((phi_deg / 0.5).astype(np.int32), 0, 719)
        occupied = np.zeros(360 * 720, np.uint8)
        occupied[rows * 720 + cols] = 1
        seen = theta_deg[np.isfinite(theta_deg)]  # a NaN point (allowed in memory) has no zenith angle
        span = np.array([seen.min(), seen.max()] if seen.size else [np.inf, -np.inf], np.float32)
        return cls(hist.astype(np.int64), occupied, span)

    def add(self, other: _Survey) -> _Survey:
        lo, hi = min(self.theta_span[0], other.theta_span[0]), max(self.theta_span[1], other.theta_span[1])
        return _Survey(self.azimuth_hist + other.azimuth_hist, self.occupied | other.occupied,
                       np.array([lo, hi], np.float32))

    @property
    def area_deg2(self) -> float:
        return float(np.count_nonzero(self.occupied)) * 0.25


def estimate_step_deg(theta_deg: np.ndarray, phi_deg: np.ndarray, *, n_total: int | None = None) -> float:
    """Angular sampling step of a scan from its point density over the occupied directions.

    ``theta_deg``/``phi_deg`` may be a subsample of a scan of ``n_total`` points.
    """
    return _rounded_step(occupied_area_deg2(theta_deg, phi_deg), n_total or theta_deg.size)


def _rounded_step(area_deg2: float, n: int) -> float:
    """The step of ``n`` points spread over ``area_deg2``, to 2 significant digits."""
    step = float(np.sqrt(area_deg2 / max(n, 1)))
    mag = 10 ** np.floor(np.log10(step))
    return float(np.round(step / mag, 1) * mag)


class PointSource(Protocol):
    """What :func:`binned_map` reads points from (held in memory, or a file's records)."""

    n: int
    limits: tuple[float, float] | None

    def survey(self, stride: int) -> _Survey: ...

    def bin(self, start: int, stop: int, grid: _Grid, scratch: _Scratch) -> _Partial | None: ...


class _ArrayPoints:
    """Points held in memory (float64 xyz, normalised intensity), handed out in float32 chunks."""

    def __init__(self, xyz: np.ndarray, intensity: np.ndarray):
        self.xyz, self.intensity, self.n = xyz, intensity, int(xyz.shape[0])
        self.limits: tuple[float, float] | None = (0.0, 1.0)

    def survey(self, stride: int) -> _Survey:
        t, p, _ = _angles32(self.xyz[::stride])
        return _Survey.of_angles(t, p)

    def bin(self, start: int, stop: int, grid: _Grid, scratch: _Scratch) -> _Partial | None:
        """Points ``start`` to ``stop`` binned on ``grid`` (their float32 angles, by numpy)."""
        t, p, r = _angles32(self.xyz[start:stop])
        return _Partial.of(grid.cells(t, p), r, np.asarray(self.intensity[start:stop], dtype=np.float32))


def reflectance_map(xyz_socs: np.ndarray, intensity: np.ndarray, *, step_deg: float | None = None,
                    progress: ProgressCallback | None = None) -> ReflectanceMap:
    """Bin a scan into a reflectance map.

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        Points in the scanner frame, metres.
    intensity : (N,) float array
        Normalised intensity in [0, 1].
    step_deg : float, optional, keyword-only
        Cell size in degrees. Default: 1.2x the scan's own angular step,
        estimated from its point density (so every cell of a surface gets a
        point), coarsened if needed to stay below ``MAX_AUTO_CELLS`` cells.
    progress : callable, optional

    Returns
    -------
    ReflectanceMap

    Notes
    -----
    One pass over the points in chunks on two threads, angles and binning fused: a strided survey of
    about two million points (every point of smaller scans) gives the step and the azimuth origin, then each
    chunk's (cheap, float32) angles are binned at once on absolute zenith rows, so the zenith range needs no
    pass of its own. Cells are indexed column by column, so a chunk of a line scanner's points (a few
    vertical lines) touches a compact range of cells. Extra memory is 16 bytes per cell plus two chunks.
    """
    xyz_socs = require_points(xyz_socs, "reflectance map", finite=False, dtype=None)
    intensity = np.asarray(intensity)
    if intensity.shape != (xyz_socs.shape[0],):
        raise InputError("reflectance map: intensity must have one value per point")
    return binned_map(_ArrayPoints(xyz_socs, intensity), step_deg=step_deg, progress=progress)


def _check_step(step_deg: float | None) -> None:
    if step_deg is not None and not (np.isfinite(step_deg) and 0 < step_deg <= 10):
        raise InputError(f"reflectance map step must be in (0, 10] degrees, got {step_deg}")


def binned_map(points: PointSource, *, step_deg: float | None = None,
               progress: ProgressCallback | None = None) -> ReflectanceMap:
    """The reflectance map of a point source (see :func:`reflectance_map`, :func:`reflectance_map_from_file`).

    ``points`` has ``n``, ``limits`` (the raw intensity range mapped onto [0, 1]; None: found while binning),
    ``survey(stride)`` (the :class:`_Survey` of every ``stride``-th point) and ``bin(start, stop, grid,
    scratch)`` (the :class:`_Partial` of points ``start`` to ``stop``). The chunks' sums are merged and the
    cells finished by the compiled loops (:mod:`lidar.native`).
    """
    _check_step(step_deg)
    n = points.n
    stride = max(1, n // 2_000_000)
    survey = points.survey(stride)
    hist = survey.azimuth_hist
    report(progress, 0.1, "angles")
    if step_deg is None:
        area = survey.area_deg2
        step_deg = 1.2 * _rounded_step(area, n)
        floor = float(np.sqrt(area / MAX_AUTO_CELLS))
        if floor > step_deg:
            step_deg = float(np.ceil(floor * 1e4) / 1e4)
    phi0, full = _azimuth_origin_from_hist(hist)
    inv = np.float32(1.0 / step_deg)
    # rows are absolute (floor(theta / step)); the survey's range plus a margin holds every point
    margin = int(np.ceil(2.0 / step_deg)) + 2
    row_lo = max(0, int(np.floor(float(survey.theta_span[0]) / step_deg)) - margin)
    row_hi = int(np.floor(float(survey.theta_span[1]) / step_deg)) + margin
    height = row_hi - row_lo + 1
    width = int(np.ceil(360.0 / step_deg)) if full else \
        min(int(np.ceil(_azimuth_span(hist, phi0) / step_deg)) + 1 + margin, int(np.ceil(360.0 / step_deg)))
    if height * width > 80_000_000:
        raise InputError(f"reflectance map of {height}x{width} cells is too large; use a coarser step than "
                         f"{step_deg:.4f} deg")
    acc = _Accumulator(height * width)  # loads the compiled loops first: a missing library is one error, at once
    starts = list(range(0, n, CHUNK))
    grid = _Grid(phi0=float(phi0), inv=inv, row_lo=row_lo, height=height, width=width)
    slots = [_Scratch() for _ in range(BATCH)]  # chunk k is binned in slots[k % BATCH]

    def bin_chunk(job: tuple[int, _Scratch]) -> _Partial | None:
        start, scratch = job
        return points.bin(start, min(start + CHUNK, n), scratch=scratch, grid=grid)  # both threads bin at once

    # the chunks' sums are added in file order, whichever thread finishes first: float32 sums in another
    # order round differently, and the map (and every window planned from it) would depend on the timing.
    # At most BATCH chunks are read ahead of the last one added (bounded memory, and chunk k's slot is free
    # again once chunk k - BATCH is added); the threads never wait for a whole batch to be added.
    ahead: deque = deque()
    with ThreadPoolExecutor(max_workers=2) as pool:
        for k, start in enumerate(starts):
            if len(ahead) == BATCH:
                acc.merge(ahead.popleft().result())
            ahead.append(pool.submit(bin_chunk, (start, slots[k % BATCH])))
            if k % BATCH == 0:
                report(progress, 0.1 + 0.9 * start / n, "binning")
        while ahead:
            acc.merge(ahead.popleft().result())
    report(progress, 1.0, "binning")
    return acc.finish(points.limits, height, width, row_lo, phi0, float(step_deg), full, n)


@dataclass(frozen=True)
class _Grid:
    """Where a point falls in the map being binned.

    Absolute zenith rows from ``row_lo``, azimuth columns from ``phi0``, cells of ``1 / inv`` degrees, indexed
    column by column (a few scan lines are a compact range).
    """

    phi0: float
    inv: np.float32
    row_lo: int
    height: int
    width: int

    def cells(self, t: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Cell indices of float32 angles in degrees (both overwritten)."""
        p -= np.float32(self.phi0)
        p += np.float32(360.0) * (p < 0)  # masks as factors: masked assignment is 4x slower
        p -= np.float32(360.0) * (p >= 360.0)
        t *= self.inv
        row = t.astype(np.int32)
        row -= self.row_lo
        p *= self.inv
        col = p.astype(np.int32)
        np.clip(row, 0, self.height - 1, out=row)
        np.clip(col, 0, self.width - 1, out=col)
        idx = col.astype(np.int64)
        idx *= self.height
        idx += row
        return idx


@dataclass
class _Partial:
    """One chunk's points binned over the cell range they cover (``lo`` to ``lo + count.size``).

    Counts in int64 and sums in float64 as ``np.bincount`` gives them (added point by point in file order);
    they are rounded to the map's int32 and float32 when merged.
    """

    lo: int
    count: np.ndarray
    sum_i: np.ndarray
    sum_r: np.ndarray
    max_i: np.ndarray
    i_lo: float
    i_hi: float

    @classmethod
    def of(cls, idx: np.ndarray, r: np.ndarray, inten: np.ndarray) -> _Partial | None:
        if idx.size == 0:
            return None
        lo = int(idx.min())
        idx -= lo
        span = int(idx.max()) + 1
        max_i = np.full(span, -np.inf, np.float32)
        np.maximum.at(max_i, idx, inten)
        return cls(lo, np.bincount(idx, minlength=span), np.bincount(idx, weights=inten, minlength=span),
                   np.bincount(idx, weights=r, minlength=span), max_i, float(inten.min()), float(inten.max()))

    @classmethod
    def of_records(cls, lib, records: np.ndarray, n: int, record_length: int, scales: np.ndarray,
                   offsets: np.ndarray, grid: _Grid, scratch: _Scratch) -> _Partial:
        """The partial of ``n`` LAS records (raw bytes) by the compiled loops (:meth:`of` of their float32 angles).

        Its arrays are ``scratch``'s, valid until the scratch bins another chunk.
        """
        cell, r, inten = scratch.take("cell", n, np.int64), scratch.take("r", n, np.float32), \
            scratch.take("i", n, np.float32)
        cell_span, inten_span = np.empty(2, np.int64), np.empty(2, np.float32)
        lib.bs_record_cells(records, n, record_length, scales, offsets, ATAN_DEG32, grid.phi0, grid.inv,
                            grid.row_lo, grid.height, grid.width, cell, r, inten, cell_span, inten_span)
        lo, span = int(cell_span[0]), int(cell_span[1] - cell_span[0]) + 1
        count, sum_i, sum_r = (scratch.take(name, span, dtype, fill=0) for name, dtype in
                               (("count", np.int64), ("sum_i", np.float64), ("sum_r", np.float64)))
        max_i = scratch.take("max_i", span, np.float32, fill=-np.inf)
        lib.bs_cell_sums(cell, r, inten, n, lo, count, sum_i, sum_r, max_i)
        return cls(lo, count, sum_i, sum_r, max_i, float(inten_span[0]), float(inten_span[1]))


class _Scratch:
    """Arrays a chunk is binned in, kept for the next chunk.

    Fresh memory costs a page fault per 4 KiB page the first time it is written, and memory handed back costs
    the other threads' address translations: allocated anew for each chunk, a 19 M-point scan's chunks faulted
    in over 200 MB.
    """

    def __init__(self) -> None:
        self._arrays: dict[str, np.ndarray] = {}

    def take(self, name: str, n: int, dtype, *, fill: float | None = None) -> np.ndarray:
        """A 1-D array of ``n`` elements (filled with ``fill`` if given): the memory of the last one of that name."""
        a = self._arrays.get(name)
        if a is None or a.size < n or a.dtype != np.dtype(dtype):
            a = self._arrays[name] = np.empty(max(n, 1), dtype)
        view = a[:n]
        if fill is not None:
            view.fill(fill)
        return view


class _Accumulator:
    """Per-cell count, intensity sum and maximum, range sum over chunks of cell indices."""

    def __init__(self, cells: int):
        # zeroed lazily, a huge page at a time (numpy asks for them for large arrays): the calling thread faults
        # the cells in as it adds the first chunks, while the other threads bin; mapping all 110 MB at once
        # beforehand (MAP_POPULATE) kept both cores waiting, 0.025-0.05 s longer for an 18.6 M-point scan
        self.count: np.ndarray = np.zeros(cells, np.int32)
        self.sum_i: np.ndarray = np.zeros(cells, np.float32)
        self.sum_r: np.ndarray = np.zeros(cells, np.float32)
        self.max_i: np.ndarray = np.zeros(cells, np.float32)
        self.max_i.fill(-np.inf)
        self.i_lo, self.i_hi = np.inf, -np.inf
        self.lib = coarse_map_library()

    def merge(self, part: _Partial | None) -> None:
        """Add one chunk's binned sums (:class:`_Partial`) into the map's cells, rounded to float32 first."""
        if part is None:
            return
        sl = slice(part.lo, part.lo + part.count.size)
        # one pass: counts and sums rounded to int32 and float32 and added, maxima kept
        self.lib.bs_merge(part.count.size, part.count, part.sum_i, part.sum_r, part.max_i, self.count[sl],
                          self.sum_i[sl], self.sum_r[sl], self.max_i[sl])
        self.i_lo, self.i_hi = min(self.i_lo, part.i_lo), max(self.i_hi, part.i_hi)

    def finish(self, limits, height, width, row_lo, phi0, step, full, n) -> ReflectanceMap:
        lo, hi = limits if limits is not None else (self.i_lo, self.i_hi)
        scale = np.float32(1.0 / (hi - lo)) if hi > lo else np.float32(0.0)
        normalise = limits != (0.0, 1.0)  # raw values binned: normalise the cells (an affine map commutes with means)
        row_used, col_used = self._finish_cells(height, width, normalise, np.float32(lo), scale)
        count, sum_i, sum_r, max_i = self.count, self.sum_i, self.sum_r, self.max_i

        def grid(a):  # column-major storage -> (rows=theta, cols=phi) view
            return a.reshape(width, height).T

        # trim the survey's margins: empty rows above and below, empty columns on the right
        rows, cols = np.flatnonzero(row_used), np.flatnonzero(col_used)
        r0, r1 = (int(rows[0]), int(rows[-1]) + 1) if rows.size else (0, height)
        c1 = width if full or not cols.size else int(cols[-1]) + 1
        cut = (slice(r0, r1), slice(0, c1))
        return ReflectanceMap(
            theta0_deg=float((row_lo + r0) * step), phi0_deg=float(phi0), step_deg=float(step),
            max_intensity=grid(max_i)[cut], mean_intensity=grid(sum_i)[cut], range_m=grid(sum_r)[cut],
            count=grid(count)[cut], full_circle=full, n_points=n,
        )

    def _finish_cells(self, height, width, normalise, lo, scale) -> tuple[np.ndarray, np.ndarray]:
        """The cells finished in place by the compiled loop; the rows and columns used.

        Sums become means, intensities are normalised (``(v - lo) * scale`` clipped to [0, 1]) and the maxima of
        empty cells NaN; half the columns on each of two threads.
        """
        lib = self.lib
        halves = [(0, width // 2), (width // 2, width)]
        rows = [np.zeros(height, np.uint8) for _ in halves]
        col_used = np.zeros(width, np.uint8)

        def run(k: int) -> None:
            c0, c1 = halves[k]
            lib.bs_finish(height, c0, c1, int(normalise), lo, scale, self.count, self.sum_i, self.sum_r, self.max_i,
                          rows[k], col_used[c0:c1])

        with ThreadPoolExecutor(max_workers=2) as pool:
            list(pool.map(run, range(2)))
        return (rows[0] | rows[1]).astype(bool), col_used.astype(bool)


def _azimuth_origin_from_hist(hist: np.ndarray) -> tuple[float, bool]:
    """Start of the azimuth coverage: the end of the largest empty gap of a 0.1-degree histogram."""
    occupied = hist > 0
    if occupied.all():
        return 0.0, True
    empty = ~occupied
    doubled = np.concatenate([empty, empty]).astype(np.int8)
    # run lengths of empty bins, vectorised
    edges = np.diff(np.concatenate([[0], doubled, [0]]))
    starts = np.nonzero(edges == 1)[0]
    ends = np.nonzero(edges == -1)[0]
    lengths = ends - starts
    k = int(np.argmax(lengths))
    if lengths[k] >= 3600:
        return 0.0, True
    start_bin = ends[k] % 3600
    origin = start_bin / 10.0 - 0.1  # one bin of slack
    if origin >= 180.0:
        origin -= 360.0
    return origin, False


def _azimuth_span(hist: np.ndarray, phi0: float) -> float:
    """Azimuth extent (degrees) of the occupied bins measured from ``phi0``."""
    centres = (np.nonzero(hist > 0)[0] + 1) / 10.0  # upper edge of each occupied bin
    return float(np.max(np.mod(centres - phi0, 360.0))) + 0.1


def reduce_map(rmap: ReflectanceMap, *, max_cells: int = 1_000_000) -> ReflectanceMap:
    """The same map on cells ``k`` times larger (the smallest integer ``k`` that fits ``max_cells``).

    Maximum intensity keeps the brightest return of each block, so small
    targets stay visible; mean intensity and range are count-weighted means.
    Used to keep a map small enough to store with the epoch and draw fast.

    Parameters
    ----------
    rmap : ReflectanceMap
    max_cells : int, keyword-only
        Upper bound on the reduced map's cell count (default one million).

    Returns
    -------
    ReflectanceMap
        ``rmap`` itself when it already fits.
    """
    if max_cells < 1:
        raise InputError(f"max_cells must be positive, got {max_cells}")
    h, w = rmap.shape
    k = int(np.ceil(np.sqrt(h * w / max_cells)))
    while k > 1 and -(-h // k) * -(-w // k) > max_cells:
        k += 1
    if k <= 1:
        return rmap
    hh, ww = -(-h // k) * k, -(-w // k) * k

    def blocks(a, fill):
        out = np.full((hh, ww), fill, dtype=a.dtype)
        out[:h, :w] = a
        return out.reshape(hh // k, k, ww // k, k)

    count = blocks(rmap.count, 0).sum(axis=(1, 3), dtype=np.int64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mx = np.fmax.reduce(np.fmax.reduce(blocks(rmap.max_intensity, np.float32(np.nan)), axis=3), axis=1)
        w_mean = blocks(np.nan_to_num(rmap.mean_intensity) * rmap.count, np.float32(0)).sum(axis=(1, 3)) / count
        w_range = blocks(np.nan_to_num(rmap.range_m) * rmap.count, np.float32(0)).sum(axis=(1, 3)) / count
    empty = count == 0
    mx[empty] = np.nan
    return ReflectanceMap(theta0_deg=rmap.theta0_deg, phi0_deg=rmap.phi0_deg, step_deg=rmap.step_deg * k,
                          max_intensity=mx.astype(np.float32), mean_intensity=w_mean.astype(np.float32),
                          range_m=w_range.astype(np.float32), count=count.astype(np.int32),
                          full_circle=rmap.full_circle, n_points=rmap.n_points)


class _LasPoints(LasRecords):
    """An uncompressed LAS file's point records (:class:`lidar.io.las.LasRecords`), binned in float32.

    Only X, Y, Z and the intensity of each record are touched: the scan is never held as float64 arrays.
    The raw intensity is binned and the map normalised over the file's own range afterwards, exactly as
    :func:`lidar.io.read_scan` normalises a LAS file's intensity.
    """

    def __init__(self, las: LasFile):
        super().__init__(las)
        self.scales, self.offsets = las.scales, las.offsets
        self.limits: tuple[float, float] | None = None
        self._batch: tuple[int, np.ndarray] | None = None  # the mapped records of the batch being binned
        self._batch_lock = threading.Lock()

    def close(self) -> None:
        self._batch = None
        super().close()

    def survey(self, stride: int) -> _Survey:
        """The survey of every ``stride``-th point, a window of about 32 MiB at a time on two threads.

        Every page of the file is touched (a sampled record every few hundred bytes): each window costs a
        mapping and an unmapping, and 8 MiB windows took 0.012 s longer over a 532 MB file.
        """
        window = max(1, (2**25 // self.dtype.itemsize) // stride) * stride
        lib, size = coarse_map_library(), self.dtype.itemsize

        def sample(start: int) -> _Survey:
            stop = min(start + window, self.n)
            raw = self.raw(start, stop)
            part = _Survey.empty()
            lib.bs_record_survey(raw, -(-(stop - start) // stride), size, stride, self.scales, self.offsets,
                                 ATAN_DEG32, part.azimuth_hist, part.occupied, part.theta_span)
            return part

        total = _Survey.empty()
        with ThreadPoolExecutor(max_workers=2) as pool:
            for part in pool.map(sample, range(0, self.n, window)):
                total = total.add(part)
        return total

    def bin(self, start: int, stop: int, grid: _Grid, scratch: _Scratch) -> _Partial | None:
        """Records ``start`` to ``stop`` binned on ``grid`` in ``scratch`` by the compiled loops."""
        return _Partial.of_records(coarse_map_library(), self._batch_records(start, stop), stop - start, self.dtype.itemsize,
                                   self.scales, self.offsets, grid, scratch)

    def _batch_records(self, start: int, stop: int) -> np.ndarray:
        """Records ``start`` to ``stop`` of one chunk, from one mapping the chunks of its batch share.

        A mapping costs a call and an unmapping however small: one a batch (``BATCH`` chunks) instead of one a
        chunk. The batch's mapping is kept until a chunk of the next batch asks for its own.
        """
        span = BATCH * CHUNK
        first = start - start % span
        with self._batch_lock:
            if self._batch is None or self._batch[0] != first:
                self._batch = (first, self.raw(first, min(first + span, self.n)))
            raw = self._batch[1]
        size = self.dtype.itemsize
        return raw[(start - first) * size:(stop - first) * size]


def reflectance_map_from_file(path: str | os.PathLike, *, step_deg: float | None = None,
                              progress: ProgressCallback | None = None) -> ReflectanceMap:
    """The reflectance map of a scan file, without holding the scan in memory where the format allows it.

    Uncompressed LAS is read straight from its point records in parallel chunks, its angles computed and
    binned in the same pass (:func:`binned_map`): the map is the one :func:`reflectance_map` makes of the
    scan :func:`lidar.io.read_scan` reads. Other formats are read whole first.

    Parameters
    ----------
    path : path-like
        A single-scan file.
    step_deg : float, optional, keyword-only
        Cell size (default: from the scan, see :func:`reflectance_map`).
    progress : callable, optional

    Returns
    -------
    ReflectanceMap

    Raises
    ------
    ScanFormatError
        The file cannot be read.
    InputError
        The scan has no intensity.
    """
    p = Path(path)
    if sniff_format(p) == "las":
        las = open_las(p)
        if not las.compressed:
            points = _LasPoints(las)
            try:
                return binned_map(points, step_deg=step_deg, progress=progress)
            finally:
                points.close()
    scan = read_scan(p, progress=progress)
    if scan.intensity is None:
        raise InputError(f"{p}: the scan has no intensity values; reflector detection needs them "
                         "(export the scan with intensity/reflectance)")
    return reflectance_map(scan.xyz_socs, scan.intensity, step_deg=step_deg, progress=progress)

"""Reflectance maps: a coarse scan binned on a (theta, phi) grid.

Each cell holds the maximum and mean normalised intensity, the mean range and
the number of points. The azimuth origin of the grid is placed in the largest
empty azimuth gap of the scan, so no target is cut in two by the 0/360 seam;
a scan covering the full circle is marked ``full_circle`` and its first and
last columns are neighbours.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from lidar.angles import direction_from_angles, wrap_phi
from common.validation import require_points
from common.errors import InputError
from common.progress import ProgressCallback, report

CHUNK = 1_000_000
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
    x = xyz[:, 0].astype(np.float32)
    y = xyz[:, 1].astype(np.float32)
    z = xyz[:, 2].astype(np.float32)
    horiz = np.hypot(x, y)
    rng = np.hypot(horiz, z)
    theta = np.arctan2(horiz, z)
    theta *= np.float32(180.0 / np.pi)
    phi = np.arctan2(y, x)
    phi *= np.float32(180.0 / np.pi)
    phi[phi < 0] += np.float32(360.0)
    return theta, phi, rng


def occupied_area_deg2(theta_deg: np.ndarray, phi_deg: np.ndarray) -> float:
    """Area (square degrees of the angle grid) of the directions a scan covers, in 0.5-degree cells."""
    rows = np.clip((theta_deg / 0.5).astype(np.int32), 0, 359)
    cols = np.clip((phi_deg / 0.5).astype(np.int32), 0, 719)
    return float(np.count_nonzero(np.bincount(rows * 720 + cols, minlength=360 * 720))) * 0.25


def estimate_step_deg(theta_deg: np.ndarray, phi_deg: np.ndarray, *, n_total: Optional[int] = None) -> float:
    """Angular sampling step of a scan from its point density over the occupied directions.

    ``theta_deg``/``phi_deg`` may be a subsample of a scan of ``n_total`` points.
    """
    n = n_total or theta_deg.size
    step = float(np.sqrt(occupied_area_deg2(theta_deg, phi_deg) / max(n, 1)))
    # round to 2 significant digits
    mag = 10 ** np.floor(np.log10(step))
    return float(np.round(step / mag, 1) * mag)


def reflectance_map(xyz_socs: np.ndarray, intensity: np.ndarray, *, step_deg: Optional[float] = None,
                    progress: Optional[ProgressCallback] = None) -> ReflectanceMap:
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
    Two passes over the points in chunks, recomputing the (cheap, float32)
    angles rather than keeping them: the first finds the grid (zenith range,
    azimuth origin, step), the second accumulates. Cells are indexed column
    by column, so a chunk of a line scanner's points (a few vertical lines)
    touches a compact range of cells. Extra memory is 16 bytes per cell plus
    one chunk.
    """
    xyz_socs = require_points(xyz_socs, "reflectance map", finite=False, dtype=None)
    intensity = np.asarray(intensity)
    if intensity.shape != (xyz_socs.shape[0],):
        raise InputError("reflectance map: intensity must have one value per point")
    if step_deg is not None and not (np.isfinite(step_deg) and 0 < step_deg <= 10):
        raise InputError(f"reflectance map step must be in (0, 10] degrees, got {step_deg}")
    n = xyz_socs.shape[0]
    starts = list(range(0, n, CHUNK))
    stride = max(1, n // 2_000_000)

    def survey(start: int):
        t, p, _ = _angles32(xyz_socs[start:start + CHUNK])
        hist = np.bincount(np.clip((p * 10).astype(np.int32), 0, 3599), minlength=3600)
        return float(t.min()), float(t.max()), hist, t[::stride], p[::stride]

    with ThreadPoolExecutor(max_workers=2) as pool:
        parts = list(pool.map(survey, starts))
    report(progress, 0.25, "angles")
    t_lo = min(x[0] for x in parts)
    t_hi = max(x[1] for x in parts)
    hist = np.sum([x[2] for x in parts], axis=0)
    if step_deg is None:
        t_s, p_s = np.concatenate([x[3] for x in parts]), np.concatenate([x[4] for x in parts])
        step_deg = 1.2 * estimate_step_deg(t_s, p_s, n_total=n)
        floor = float(np.sqrt(occupied_area_deg2(t_s, p_s) / MAX_AUTO_CELLS))
        if floor > step_deg:
            step_deg = float(np.ceil(floor * 1e4) / 1e4)
    del parts
    phi0, full = _azimuth_origin_from_hist(hist)
    theta0 = float(np.floor(t_lo / step_deg) * step_deg)
    height = int(np.floor((t_hi - theta0) / step_deg)) + 1
    width = int(np.ceil(360.0 / step_deg)) if full else int(np.ceil(_azimuth_span(hist, phi0) / step_deg)) + 1
    if height * width > 80_000_000:
        raise InputError(f"reflectance map of {height}x{width} cells is too large; use a coarser step than "
                         f"{step_deg:.4f} deg")
    cells = height * width
    count = np.zeros(cells, np.int32)
    sum_i = np.zeros(cells, np.float32)
    sum_r = np.zeros(cells, np.float32)
    max_i = np.full(cells, -1.0, np.float32)
    inv = np.float32(1.0 / step_deg)

    def cell_index(start: int):
        t, p, r = _angles32(xyz_socs[start:start + CHUNK])
        p -= np.float32(phi0)
        p[p < 0] += np.float32(360.0)
        p[p >= 360.0] -= np.float32(360.0)
        row = ((t - np.float32(theta0)) * inv).astype(np.int64)
        col = (p * inv).astype(np.int64)
        np.clip(row, 0, height - 1, out=row)
        np.clip(col, 0, width - 1, out=col)
        idx = col * height + row  # column-major: a few scan lines are a compact index range
        lo = int(idx.min())
        idx -= lo
        return lo, idx, r

    with ThreadPoolExecutor(max_workers=2) as pool:
        for k, (lo, idx, r) in enumerate(pool.map(cell_index, starts)):
            start = starts[k]
            inten = intensity[start:start + CHUNK]
            span = int(idx.max()) + 1
            sl = slice(lo, lo + span)
            count[sl] += np.bincount(idx, minlength=span).astype(np.int32)
            sum_i[sl] += np.bincount(idx, weights=inten, minlength=span).astype(np.float32)
            sum_r[sl] += np.bincount(idx, weights=r, minlength=span).astype(np.float32)
            np.maximum.at(max_i[sl], idx, inten.astype(np.float32, copy=False))
            report(progress, 0.25 + 0.75 * min(n, start + CHUNK) / n, "binning")
    empty = count == 0
    with np.errstate(invalid="ignore", divide="ignore"):
        sum_i /= count  # in place: the sums become means
        sum_r /= count
    max_i[empty] = np.nan

    def grid(a):  # column-major storage -> (rows=theta, cols=phi) view
        return a.reshape(width, height).T

    return ReflectanceMap(
        theta0_deg=theta0, phi0_deg=float(phi0), step_deg=float(step_deg),
        max_intensity=grid(max_i), mean_intensity=grid(sum_i), range_m=grid(sum_r), count=grid(count),
        full_circle=full, n_points=n,
    )


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

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

from lidar.angles import direction_from_angles, wrap_phi
from lidar.errors import InputError
from lidar.progress import ProgressCallback, report

CHUNK = 1_000_000


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

    def cell_angles(self, row, col) -> tuple[np.ndarray, np.ndarray]:
        """(theta, phi in [0, 360)) of (fractional) cell indices, at cell centres for integers."""
        theta = self.theta0_deg + (np.asarray(row, dtype=np.float64) + 0.5) * self.step_deg
        phi = wrap_phi(self.phi0_deg + (np.asarray(col, dtype=np.float64) + 0.5) * self.step_deg)
        return theta, phi

    def cells_of(self, theta_deg, phi_deg) -> tuple[np.ndarray, np.ndarray]:
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

    def xyz_of(self, theta_deg, phi_deg, range_m) -> np.ndarray:
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


def estimate_step_deg(theta_deg: np.ndarray, phi_deg: np.ndarray, *, n_total: Optional[int] = None) -> float:
    """Angular sampling step of a scan from its point density over the occupied directions.

    ``theta_deg``/``phi_deg`` may be a subsample of a scan of ``n_total`` points.
    """
    n = n_total or theta_deg.size
    # Occupied 0.5-degree cells (sin(theta) corrects the azimuth spacing of a line scanner).
    rows = np.clip((theta_deg / 0.5).astype(np.int32), 0, 359)
    cols = np.clip((phi_deg / 0.5).astype(np.int32), 0, 719)
    occupied = np.bincount(rows * 720 + cols, minlength=360 * 720) > 0
    area = np.count_nonzero(occupied) * 0.25
    step = float(np.sqrt(area / max(n, 1)))
    # round to 2 significant digits
    mag = 10 ** np.floor(np.log10(step))
    return float(np.round(step / mag, 1) * mag)


def _azimuth_origin(phi_deg: np.ndarray) -> tuple[float, bool]:
    """Start of the scan's azimuth coverage: the end of its largest empty gap (0.1-degree bins)."""
    hist = np.bincount(np.clip((phi_deg * 10).astype(np.int32), 0, 3599), minlength=3600) > 0
    if hist.all():
        return 0.0, True
    empty = ~hist
    # longest circular run of empty bins
    doubled = np.concatenate([empty, empty])
    best_len, best_end, run = 0, 0, 0
    for i, e in enumerate(doubled):
        run = run + 1 if e else 0
        if run > best_len:
            best_len, best_end = run, i
    if best_len >= 3600:
        return 0.0, True
    start_bin = (best_end + 1) % 3600
    origin = start_bin / 10.0 - 0.1  # one bin of slack
    if origin >= 180.0:
        origin -= 360.0
    return origin, False


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
        estimated from its point density (so every cell of a surface gets a point).
    progress : callable, optional

    Returns
    -------
    ReflectanceMap
    """
    xyz_socs = np.asarray(xyz_socs)
    intensity = np.asarray(intensity)
    if xyz_socs.ndim != 2 or xyz_socs.shape[1] != 3 or xyz_socs.shape[0] == 0:
        raise InputError(f"reflectance map needs an (N, 3) array of points, got shape {xyz_socs.shape}")
    if intensity.shape != (xyz_socs.shape[0],):
        raise InputError("reflectance map: intensity must have one value per point")
    if step_deg is not None and not (np.isfinite(step_deg) and 0 < step_deg <= 10):
        raise InputError(f"reflectance map step must be in (0, 10] degrees, got {step_deg}")
    n = xyz_socs.shape[0]
    theta = np.empty(n, np.float32)
    phi = np.empty(n, np.float32)
    rng = np.empty(n, np.float32)
    starts = range(0, n, CHUNK)

    def angles(start: int) -> None:
        t, p, r = _angles32(xyz_socs[start:start + CHUNK])
        theta[start:start + CHUNK], phi[start:start + CHUNK], rng[start:start + CHUNK] = t, p, r

    with ThreadPoolExecutor(max_workers=2) as pool:
        list(pool.map(angles, starts))
    report(progress, 0.3, "angles")
    if step_deg is None:
        stride = max(1, n // 2_000_000)
        step_deg = 1.2 * estimate_step_deg(theta[::stride], phi[::stride], n_total=n)
    phi0, full = _azimuth_origin(phi)
    theta0 = float(np.floor(theta.min() / step_deg) * step_deg)
    height = int(np.floor((float(theta.max()) - theta0) / step_deg)) + 1
    width = int(np.ceil(360.0 / step_deg)) if full else \
        int(np.floor(float(np.max(np.mod(phi - np.float32(phi0), 360.0))) / step_deg)) + 1
    if height * width > 60_000_000:
        raise InputError(f"reflectance map of {height}x{width} cells is too large; use a coarser step than {step_deg} deg")
    cells = height * width
    count = np.zeros(cells, np.int64)
    sum_i = np.zeros(cells, np.float64)
    sum_r = np.zeros(cells, np.float64)
    max_i = np.full(cells, -1.0, np.float32)
    inv = np.float32(1.0 / step_deg)

    def cell_index(start: int) -> np.ndarray:
        t = theta[start:start + CHUNK]
        p = phi[start:start + CHUNK] - np.float32(phi0)
        p[p < 0] += np.float32(360.0)
        p[p >= 360.0] -= np.float32(360.0)
        row = ((t - np.float32(theta0)) * inv).astype(np.int64)
        col = (p * inv).astype(np.int64)
        np.clip(row, 0, height - 1, out=row)
        np.clip(col, 0, width - 1, out=col)
        return row * width + col

    with ThreadPoolExecutor(max_workers=2) as pool:
        for k, idx in enumerate(pool.map(cell_index, starts)):
            start = k * CHUNK
            inten = intensity[start:start + CHUNK]
            count += np.bincount(idx, minlength=cells)
            sum_i += np.bincount(idx, weights=inten, minlength=cells)
            sum_r += np.bincount(idx, weights=rng[start:start + CHUNK], minlength=cells)
            np.maximum.at(max_i, idx, inten.astype(np.float32, copy=False))
            report(progress, 0.3 + 0.7 * min(n, start + CHUNK) / n, "binning")
    empty = count == 0
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_i = (sum_i / count).astype(np.float32)
        mean_r = (sum_r / count).astype(np.float32)
    max_i[empty] = np.nan
    return ReflectanceMap(
        theta0_deg=theta0, phi0_deg=float(phi0), step_deg=float(step_deg),
        max_intensity=max_i.reshape(height, width), mean_intensity=mean_i.reshape(height, width),
        range_m=mean_r.reshape(height, width), count=count.reshape(height, width).astype(np.int32),
        full_circle=full, n_points=n,
    )

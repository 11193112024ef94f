"""Scanner angle conventions and angular windows.

Conventions (fixed by the product's contracts):

* ``phi``: azimuth, counter-clockwise from +x in the scanner's xy plane, degrees in [0, 360).
* ``theta``: zenith angle from +z, degrees in [0, 180].

A direction is ``(sin(theta) cos(phi), sin(theta) sin(phi), cos(theta))``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, DTypeLike

from common.errors import InputError


def spherical_from_xyz(xyz_socs: np.ndarray, *, out_dtype: DTypeLike = np.float64) -> tuple[np.ndarray, np.ndarray,
                       np.ndarray]:
    """Zenith angle, azimuth and range of points in the scanner frame.

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array, metres.
    out_dtype : dtype, keyword-only
        dtype of the returned angles (float32 halves memory for reflectance maps). Default float64.

    Returns
    -------
    theta_deg : (N,) zenith angles in [0, 180].
    phi_deg : (N,) azimuths in [0, 360).
    range_m : (N,) float64 distances from the scanner origin.
    """
    x = xyz_socs[:, 0]
    y = xyz_socs[:, 1]
    z = xyz_socs[:, 2]
    horiz = np.hypot(x, y)
    rng = np.hypot(horiz, z)
    theta = np.degrees(np.arctan2(horiz, z)).astype(out_dtype, copy=False)
    phi = np.degrees(np.arctan2(y, x)).astype(out_dtype, copy=False)
    phi[phi < 0] += 360.0
    phi[phi >= 360.0] -= 360.0
    return theta, phi, rng


#: Odd minimax polynomial of atan(a) on [0, 1] in degrees: atan(a) = a * sum(c_k a^(2k)), within 2.5e-7 rad
#: (also the compiled coarse map's, lidar/native/coarse_map.c).
ATAN_DEG32 = np.degrees(np.array([0.99999611, -0.33317372, 0.19807837, -0.13233395, 0.07962432, -0.0336046,
                                 0.00681188])).astype(np.float32)


def atan2_deg32(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``degrees(arctan2(y, x))`` of float32 arrays, four times quicker than numpy's float32 ``arctan2``.

    Parameters
    ----------
    y, x : (N,) float32 arrays
        ``x`` and ``y`` are left as they are.

    Returns
    -------
    (N,) float32 array
        Angles in degrees in [-180, 180], with arctan2's signs for zeros (``atan2(-0, -1) = -180``).
        Within 3e-5 degrees of the exact angle (numpy's float32 ``arctan2`` in degrees: 2e-5), a
        thousandth of a 0.02-degree cell.

    Notes
    -----
    The coarse map of a 19-million-point scan takes two angles a point; numpy's float32 ``arctan2`` (37 ns a
    point here) was two thirds of the map's time. The angle of the smaller over the larger coordinate comes
    from a polynomial; the octant is restored with sign arithmetic (``copysign``) rather than masks, which
    numpy runs at a quarter of its arithmetic speed.
    """
    ax, ay = np.abs(x), np.abs(y)
    big = np.maximum(ax, ay)
    np.maximum(big, np.float32(1e-30), out=big)  # atan2(0, 0) = 0
    a = np.minimum(ax, ay)
    a /= big
    s = np.multiply(a, a, out=big)
    r = s * ATAN_DEG32[-1]
    for c in ATAN_DEG32[-2:0:-1]:  # Horner's scheme
        r += c
        r *= s
    r += ATAN_DEG32[0]
    r *= a  # degrees in [0, 45]
    ax -= ay
    _mirror(r, np.float32(45.0), np.copysign(np.float32(1.0), ax, out=ax))  # 90 - r where |y| > |x|
    _mirror(r, np.float32(90.0), np.copysign(np.float32(1.0), x, out=ay))  # 180 - r where x < 0
    return np.copysign(r, y, out=r)


def spherical32(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zenith angle, azimuth and range of float32 coordinates, by :func:`atan2_deg32`; overwrites its inputs.

    Parameters
    ----------
    x, y, z : (N,) float32 arrays, metres in the scanner frame
        Used as work space: their values are lost.

    Returns
    -------
    theta_deg : (N,) float32 zenith angles in [0, 180], within 3e-5 degrees.
    phi_deg : (N,) float32 azimuths in [0, 360], within 5e-5 degrees (those above 180 take one more
        rounding); one just below 360 may round to 360.0.
    range_m : (N,) float32 distances from the scanner origin.
    """
    phi = atan2_deg32(y, x)
    phi += np.float32(360.0) * (phi < 0)  # a mask as a factor: masked assignment is 4x slower
    x *= x
    y *= y
    x += y  # horizontal distance squared
    y = np.multiply(z, z, out=y)
    y += x  # range squared
    theta = atan2_deg32(np.sqrt(x, out=x), z)
    return theta, phi, np.sqrt(y, out=y)


def _mirror(r: np.ndarray, about: np.float32, sign: np.ndarray) -> None:
    """``r`` where ``sign`` is +1, ``2 * about - r`` where it is -1, in place."""
    np.subtract(about, r, out=r)
    r *= sign
    np.subtract(about, r, out=r)


def direction_from_angles(theta_deg: ArrayLike, phi_deg: ArrayLike) -> np.ndarray:
    """(..., 3) unit vectors for zenith/azimuth angles in degrees."""
    t = np.radians(np.asarray(theta_deg, dtype=np.float64))
    p = np.radians(np.asarray(phi_deg, dtype=np.float64))
    st = np.sin(t)
    return np.stack([st * np.cos(p), st * np.sin(p), np.cos(t)], axis=-1)


def wrap_phi(phi_deg: ArrayLike) -> np.ndarray:
    """Azimuth wrapped into [0, 360)."""
    return np.mod(phi_deg, 360.0)


def phi_difference(a_deg: ArrayLike, b_deg: ArrayLike) -> np.ndarray:
    """Signed smallest azimuth difference a - b in (-180, 180]."""
    d = np.mod(np.asarray(a_deg) - np.asarray(b_deg) + 180.0, 360.0) - 180.0
    return np.where(d == -180.0, 180.0, d)


@dataclass(frozen=True)
class AngularWindow:
    """A rectangular window of scanner angles, scanned on a regular grid.

    ``phi_min_deg < phi_max_deg`` always; a window across the 0/360 seam starts
    below 0 (e.g. -2 .. 3). Steps are the angular sampling intervals.
    """

    phi_min_deg: float
    phi_max_deg: float
    theta_min_deg: float
    theta_max_deg: float
    phi_step_deg: float
    theta_step_deg: float

    def __post_init__(self) -> None:
        vals = (self.phi_min_deg, self.phi_max_deg, self.theta_min_deg, self.theta_max_deg,
                self.phi_step_deg, self.theta_step_deg)
        if not all(np.isfinite(v) for v in vals):
            raise InputError(f"angular window has non-finite values: {vals}")
        if not self.phi_min_deg < self.phi_max_deg:
            raise InputError(f"angular window needs phi_min < phi_max, got {self.phi_min_deg} .. {self.phi_max_deg}")
        if self.phi_max_deg - self.phi_min_deg > 360.0:
            raise InputError("angular window spans more than 360 degrees of azimuth")
        if not 0.0 <= self.theta_min_deg < self.theta_max_deg <= 180.0:
            raise InputError(f"angular window needs 0 <= theta_min < theta_max <= 180, got "
                             f"{self.theta_min_deg} .. {self.theta_max_deg}")
        if self.phi_step_deg <= 0 or self.theta_step_deg <= 0:
            raise InputError("angular window steps must be positive")

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the scanning grid: rows along theta, columns along phi."""
        rows = int(np.floor((self.theta_max_deg - self.theta_min_deg) / self.theta_step_deg + 1e-9)) + 1
        cols = int(np.floor((self.phi_max_deg - self.phi_min_deg) / self.phi_step_deg + 1e-9)) + 1
        return rows, cols

    @property
    def n_directions(self) -> int:
        rows, cols = self.shape
        return rows * cols

    def grid(self) -> tuple[np.ndarray, np.ndarray]:
        """Flattened (theta_deg, phi_deg) of every grid direction, column by column (line scanning)."""
        rows, cols = self.shape
        theta = self.theta_min_deg + self.theta_step_deg * np.arange(rows)
        phi = self.phi_min_deg + self.phi_step_deg * np.arange(cols)
        pp, tt = np.meshgrid(phi, theta, indexing="ij")  # column-major: one vertical line per phi
        return tt.ravel(), wrap_phi(pp.ravel())

    def contains(self, theta_deg: ArrayLike, phi_deg: ArrayLike) -> np.ndarray:
        """Boolean mask of directions inside the window (azimuth seam aware)."""
        theta_deg = np.asarray(theta_deg)
        phi_rel = np.mod(np.asarray(phi_deg) - self.phi_min_deg, 360.0)
        return ((theta_deg >= self.theta_min_deg) & (theta_deg <= self.theta_max_deg)
                & (phi_rel <= self.phi_max_deg - self.phi_min_deg))

    @property
    def centre(self) -> tuple[float, float]:
        """(theta, phi) of the window centre, phi wrapped into [0, 360)."""
        return (0.5 * (self.theta_min_deg + self.theta_max_deg),
                float(wrap_phi(0.5 * (self.phi_min_deg + self.phi_max_deg))))


def window_around(theta_deg: float, phi_deg: float, half_theta_deg: float, half_phi_deg: float,
                  theta_step_deg: float, phi_step_deg: float) -> AngularWindow:
    """Window centred on a direction; the azimuth range is kept continuous across 0/360."""
    phi_c = float(wrap_phi(phi_deg))
    lo, hi = phi_c - half_phi_deg, phi_c + half_phi_deg
    if hi >= 360.0:
        lo, hi = lo - 360.0, hi - 360.0
    return AngularWindow(lo, hi, max(0.0, theta_deg - half_theta_deg), min(180.0, theta_deg + half_theta_deg),
                         phi_step_deg, theta_step_deg)


def bounding_window(theta_deg: np.ndarray, phi_deg: np.ndarray, *, margin_deg: float = 0.0,
                    theta_step_deg: float, phi_step_deg: float) -> AngularWindow | None:
    """Smallest window (seam aware) holding all given directions, plus a margin."""
    if len(theta_deg) == 0:
        return None
    phi = np.sort(wrap_phi(np.asarray(phi_deg, dtype=np.float64)))
    gaps = np.diff(np.concatenate([phi, [phi[0] + 360.0]]))
    k = int(np.argmax(gaps))  # the largest empty arc is outside the window
    start = phi[(k + 1) % len(phi)]
    width = 360.0 - gaps[k]
    if start >= 180.0 and start + width >= 360.0:
        start -= 360.0
    lo, hi = start - margin_deg, start + width + margin_deg
    if hi - lo > 360.0:
        lo, hi = 0.0, 360.0
    return AngularWindow(lo, hi, max(0.0, float(np.min(theta_deg)) - margin_deg),
                         min(180.0, float(np.max(theta_deg)) + margin_deg), phi_step_deg, theta_step_deg)

"""Movement during a fine window, from the points' own times: a train, a lorry or wind under the scanner.

A scanner sweeps a fine window in vertical lines over seconds to minutes; a train moves a deck by millimetres
for seconds. The surface around a target (the deck's underside, a girder) is scanned with the target and
moves with it, and it holds thousands of points: its ranges against time show the movement. The static
surface is a quadratic in the window's own angles, fitted robustly to every background point; the medians of
its residuals along the line of sight, bin by bin in time, are compared with their noise. Bins that depart
are a movement: their points (the target's among them) are left out of the centroid when enough remain, else
the target is flagged to be scanned again.

Examples
--------
>>> import numpy as np
>>> rng = np.random.default_rng(0)
>>> th, ph = np.meshgrid(np.linspace(80, 82, 200), np.linspace(10, 12, 200))
>>> d = np.stack([np.sin(np.radians(th)) * np.cos(np.radians(ph)), np.sin(np.radians(th)) *
...               np.sin(np.radians(ph)), np.cos(np.radians(th))], -1).reshape(-1, 3)
>>> t = np.repeat(np.arange(200) * 0.1, 200)          # 200 lines of 0.1 s
>>> r = 20.0 / d[:, 0] + rng.normal(0, 0.005, len(d))   # a wall at x = 20 m, 5 mm range noise
>>> r[(t > 8) & (t < 12)] -= 0.003                      # 3 mm toward the scanner for 4 s
>>> m = window_motion(d * r[:, None], t)
>>> m.checked, len(m.disturbed) >= 1, 2.0 < m.peak_mm < 4.0
(True, True, True)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Fewest background points for a window's movement to be checked.
MIN_POINTS = 400
#: A time bin's median residual beyond this many of its sigmas is a movement ...
THRESHOLD_SIGMA = 5.0
#: ... and beyond this size along the line of sight (metres).
MIN_MOVEMENT_M = 0.0002
#: Time bins per window (fewer when a bin would hold fewer than MIN_BIN_POINTS points).
BINS = 48
MIN_BIN_POINTS = 60
#: Residuals beyond this many robust sigmas are other surfaces, not the static one (left out of the fit).
OUTLIER_SIGMA = 6.0


@dataclass(frozen=True)
class WindowMotion:
    """What a window's background points say of movement while it was scanned.

    Attributes
    ----------
    checked : bool
        Times were there and enough background points to look.
    disturbed : tuple of (float, float)
        Time intervals (seconds, the points' clock) in which the surface moved.
    peak_mm : float
        The largest departure of a time bin along the line of sight, millimetres (signed: + away from the
        scanner).
    sigma_mm : float
        A time bin's median's typical standard deviation, millimetres.
    edges_s, offsets_m : tuple of float
        The time bins' edges (n + 1) and each bin's median range departure (n, metres; 0 outside the
        disturbed intervals): what :meth:`range_offset_m` interpolates.
    """

    checked: bool
    disturbed: tuple[tuple[float, float], ...] = ()
    peak_mm: float = 0.0
    sigma_mm: float = float("nan")
    edges_s: tuple[float, ...] = ()
    offsets_m: tuple[float, ...] = ()

    def range_offset_m(self, time_s: np.ndarray) -> np.ndarray:
        """(N,) how much longer than the static surface's the ranges read at these times (0 where undisturbed)."""
        t = np.asarray(time_s, dtype=np.float64)
        if not self.offsets_m:
            return np.zeros(t.shape)
        mids = 0.5 * (np.asarray(self.edges_s[:-1]) + np.asarray(self.edges_s[1:]))
        return np.where(self.contains(t), np.interp(t, mids, np.asarray(self.offsets_m)), 0.0)

    def contains(self, time_s: np.ndarray) -> np.ndarray:
        """(N,) whether each time falls in a disturbed interval."""
        t = np.asarray(time_s, dtype=np.float64)
        out = np.zeros(t.shape, dtype=bool)
        for a, b in self.disturbed:
            out |= (t >= a) & (t <= b)
        return out


def _design(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])


def window_motion(xyz_socs: np.ndarray, time_s: np.ndarray, *, exclude: np.ndarray | None = None,
                  threshold_sigma: float = THRESHOLD_SIGMA, min_movement_m: float = MIN_MOVEMENT_M,
                  bins: int = BINS) -> WindowMotion:
    """Whether the surface in a window moved while it was scanned, and when.

    Parameters
    ----------
    xyz_socs : (N, 3) float64
        The window's points, scanner frame, metres.
    time_s : (N,) float64
        Each point's time, seconds (NaN: unknown).
    exclude : (N,) bool, optional, keyword-only
        Points that are not the background (the target's bright points): left out.
    threshold_sigma, min_movement_m, bins : keyword-only
        A time bin departs when its median residual exceeds both ``threshold_sigma`` of its sigmas and
        ``min_movement_m``; the window's time is cut into ``bins`` bins (fewer when they would be thin).

    Returns
    -------
    WindowMotion
        ``checked`` False when the points carry no times or the background is too thin to look.
    """
    xyz = np.asarray(xyz_socs, dtype=np.float64)
    t = np.asarray(time_s, dtype=np.float64)
    keep = np.isfinite(t) & np.isfinite(xyz).all(axis=1)
    if exclude is not None:
        keep &= ~np.asarray(exclude, dtype=bool)
    if np.count_nonzero(keep) < MIN_POINTS:
        return WindowMotion(False)
    p, t = xyz[keep], t[keep]
    r = np.linalg.norm(p, axis=1)
    view = p.mean(axis=0) / np.linalg.norm(p.mean(axis=0))
    e1 = np.cross(view, [0.0, 0.0, 1.0] if abs(view[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(view, e1)
    dirs = p / r[:, None]
    u, v = dirs @ e1, dirs @ e2  # the window's own angles (radians, small)
    a = _design(u - u.mean(), v - v.mean())
    quiet = np.ones(len(r), dtype=bool)
    result = WindowMotion(False)
    for _ in range(3):  # the static surface from the quiet time only, once a movement is seen
        res, w = _static_residuals(a, r, quiet)
        result = _bins(t, res, w, threshold_sigma, min_movement_m, bins)
        if not result.checked:
            return result
        now_quiet = ~result.contains(t)
        if np.array_equal(now_quiet, quiet) or np.count_nonzero(now_quiet) < MIN_POINTS:
            break
        quiet = now_quiet
    return result


def _static_residuals(a: np.ndarray, r: np.ndarray, use: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranges less a robust quadratic surface fitted to the points ``use``; and the points it kept (inliers)."""
    w = use.copy()
    res = r - np.median(r[use])
    for _ in range(4):  # other surfaces in the window are left out as outliers
        coef, *_ = np.linalg.lstsq(a[w], r[w], rcond=None)
        res = r - a @ coef
        s = 1.4826 * float(np.median(np.abs(res[w] - np.median(res[w]))))
        w_new = use & (np.abs(res) <= OUTLIER_SIGMA * max(s, 1e-5))
        if np.array_equal(w_new, w):
            break
        w = w_new
    s = 1.4826 * float(np.median(np.abs(res[w] - np.median(res[w]))))
    return res, np.abs(res) <= OUTLIER_SIGMA * max(s, 1e-5)


def _bins(t: np.ndarray, res: np.ndarray, w: np.ndarray, threshold_sigma: float, min_movement_m: float,
          bins: int) -> WindowMotion:
    """The time bins' median residuals and the intervals whose departure exceeds their noise."""
    order = np.argsort(t[w], kind="stable")
    tw, rw = t[w][order], res[w][order]
    n_bins = int(max(1, min(bins, len(tw) // MIN_BIN_POINTS)))
    if n_bins < 4:
        return WindowMotion(False)
    edges = np.linspace(tw[0], tw[-1], n_bins + 1)
    idx = np.clip(np.searchsorted(edges, tw, side="right") - 1, 0, n_bins - 1)
    noise = 1.4826 * float(np.median(np.abs(rw - np.median(rw))))
    med = np.full(n_bins, np.nan)
    sig = np.full(n_bins, np.inf)
    for b in range(n_bins):
        sel = rw[idx == b]
        if sel.size >= MIN_BIN_POINTS // 2:
            med[b] = float(np.median(sel))
            sig[b] = 1.2533 * noise / np.sqrt(sel.size)
    centre = float(np.nanmedian(med))
    dev = med - centre
    bad = np.isfinite(dev) & (np.abs(dev) > threshold_sigma * sig) & (np.abs(dev) > min_movement_m)
    finite = np.isfinite(dev)
    peak = float(dev[finite][np.argmax(np.abs(dev[finite]))]) if finite.any() else 0.0
    sigma_mm = float(np.median(sig[np.isfinite(sig)])) * 1e3 if np.isfinite(sig).any() else float("nan")
    if not bad.any():
        return WindowMotion(True, (), peak * 1e3, sigma_mm)
    grow = bad.copy()  # one bin either side: the ramps a bin's median hides
    grow[1:] |= bad[:-1]
    grow[:-1] |= bad[1:]
    intervals = []
    b = 0
    while b < n_bins:
        if grow[b]:
            e = b
            while e + 1 < n_bins and grow[e + 1]:
                e += 1
            intervals.append((float(edges[b]), float(edges[e + 1])))
            b = e + 1
        else:
            b += 1
    offsets = np.where(grow & np.isfinite(dev), dev, 0.0)
    return WindowMotion(True, tuple(intervals), peak * 1e3, sigma_mm, tuple(float(e) for e in edges),
                        tuple(float(o) for o in offsets))

"""Span profile: mean height of the deck underside per bin along the girder lines, between two epochs."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from registration.errors import InputError


@dataclass(frozen=True)
class ProfileBin:
    """One bin of one girder line (heights along ``up`` in the campaign frame, metres)."""

    girder: int
    station_m: float
    n_from: int
    n_to: int
    mean_from_m: float
    mean_to_m: float
    std_from_m: float
    std_to_m: float

    @property
    def change_m(self) -> float:
        return self.mean_to_m - self.mean_from_m

    @property
    def sigma_change_m(self) -> float:
        if self.n_from < 2 or self.n_to < 2:
            return float("nan")
        return float(np.hypot(self.std_from_m / np.sqrt(self.n_from), self.std_to_m / np.sqrt(self.n_to)))


@dataclass(frozen=True, eq=False)
class SpanProfile:
    """Result of :func:`span_profile`.

    Attributes
    ----------
    bins : tuple of ProfileBin
    origin : (3,) array
        Station 0 (campaign frame).
    axis : (3,) array
        Horizontal unit vector along the span.
    up : (3,) array
    girder_offsets_m : tuple of float
        Lateral offset of each girder line from the axis.
    bin_m, half_width_m, band_m : float
        Parameters used.
    """

    bins: tuple[ProfileBin, ...]
    origin: np.ndarray
    axis: np.ndarray
    up: np.ndarray
    girder_offsets_m: tuple[float, ...]
    bin_m: float
    half_width_m: float
    band_m: float

    def station_of(self, xyz: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(np.asarray(xyz, dtype=np.float64)) - self.origin) @ self.axis

    def girder_of(self, xyz: np.ndarray) -> np.ndarray:
        lat = (np.atleast_2d(np.asarray(xyz, dtype=np.float64)) - self.origin) @ np.cross(self.up, self.axis)
        return np.argmin(np.abs(lat[:, None] - np.asarray(self.girder_offsets_m)[None, :]), axis=1)

    def table(self) -> list[dict]:
        return [{"girder": b.girder + 1, "station_m": round(b.station_m, 3), "n_from": b.n_from, "n_to": b.n_to,
                 "mean_from_m": b.mean_from_m, "mean_to_m": b.mean_to_m, "std_from_mm": b.std_from_m * 1e3,
                 "std_to_mm": b.std_to_m * 1e3, "change_mm": b.change_m * 1e3,
                 "sigma_change_mm": b.sigma_change_m * 1e3} for b in self.bins]


def span_profile(xyz_from: np.ndarray, xyz_to: np.ndarray, girder_points: np.ndarray, *, bin_m: float = 2.5,
                 half_width_m: float = 0.5, band_m: float = 0.15, up: Sequence[float] = (0.0, 0.0, 1.0),
                 origin: Optional[np.ndarray] = None, min_points: int = 10) -> SpanProfile:
    """Mean height and its spread per bin along each girder line, in two registered epochs.

    Parameters
    ----------
    xyz_from, xyz_to : (N, 3), (M, 3) float64 arrays, metres
        The two epochs' clouds in the same (campaign) frame.
    girder_points : (K, 3) array, K >= 2
        Points on the deck underside marking the girder lines (the measurement targets). Lines are
        told apart by their lateral offsets (more than 1 m apart).
    bin_m : float, keyword-only
        Bin length along the span (default 2.5 m, as in the dissertation's whole-bridge comparison).
    half_width_m : float, keyword-only
        Points within this lateral distance of a girder line are used (default 0.5 m).
    band_m : float, keyword-only
        ... and within this distance of the underside level through the line's targets (default 15 cm).
    up : (3,) sequence
        Vertical direction of the campaign frame.
    origin : (3,) array, optional
        Station 0 (default: the girder point with the smallest station).
    min_points : int
        Bins with fewer points in either epoch are left out.

    Returns
    -------
    SpanProfile
    """
    a = np.asarray(xyz_from, dtype=np.float64)
    b = np.asarray(xyz_to, dtype=np.float64)
    g = np.asarray(girder_points, dtype=np.float64)
    if g.ndim != 2 or g.shape[1] != 3 or len(g) < 2 or not np.all(np.isfinite(g)):
        raise InputError("a span profile needs at least two finite girder points (measurement targets)")
    if not (bin_m > 0 and half_width_m > 0 and band_m > 0):
        raise InputError("span profile: bin length, half width and band must be positive")
    up_v = np.asarray(up, dtype=np.float64)
    up_v = up_v / np.linalg.norm(up_v)
    gh = g - np.outer(g @ up_v, up_v)
    c = gh.mean(axis=0)
    _, _, vt = np.linalg.svd(gh - c)
    axis = vt[0] - (vt[0] @ up_v) * up_v
    axis /= np.linalg.norm(axis)
    side = np.cross(up_v, axis)
    if origin is None:
        s_g = (g - c) @ axis
        if np.median(s_g) < 0:  # stations grow along the span from the first target
            axis, side = -axis, -side
            s_g = -s_g
        origin = c + axis * s_g.min()  # stations and offsets are horizontal: the origin's height does not matter
    origin = np.asarray(origin, dtype=np.float64)
    lat_g = (g - origin) @ side
    order = np.argsort(lat_g)
    groups = [[order[0]]]
    for k in order[1:]:
        if lat_g[k] - lat_g[groups[-1][-1]] > 1.0:
            groups.append([k])
        else:
            groups[-1].append(k)
    offsets = tuple(float(lat_g[grp].mean()) for grp in groups)
    bins = []
    for gi, grp in enumerate(groups):
        s_t = (g[grp] - origin) @ axis
        h_t = g[grp] @ up_v
        fit = np.polyfit(s_t, h_t, 1) if len(grp) >= 2 and np.ptp(s_t) > 1.0 else np.array([0.0, h_t.mean()])
        lo = np.floor(s_t.min() / bin_m) * bin_m - bin_m
        hi = np.ceil(s_t.max() / bin_m) * bin_m + bin_m
        per_epoch = []
        for xyz in (a, b):
            s = (xyz - origin) @ axis
            lat = (xyz - origin) @ side
            h = xyz @ up_v
            sel = (np.abs(lat - offsets[gi]) <= half_width_m) & (np.abs(h - np.polyval(fit, s)) <= band_m) & \
                  (s >= lo) & (s < hi)
            k = np.floor((s[sel] - lo) / bin_m).astype(np.int64)
            nb = int(round((hi - lo) / bin_m))
            n = np.bincount(k, minlength=nb)
            sh = np.bincount(k, weights=h[sel], minlength=nb)
            shh = np.bincount(k, weights=(h[sel] - sh[k] / np.maximum(n[k], 1)) ** 2, minlength=nb)
            with np.errstate(invalid="ignore", divide="ignore"):
                per_epoch.append((n, sh / n, np.sqrt(shh / np.maximum(n - 1, 1))))
        (n1, m1, s1), (n2, m2, s2) = per_epoch
        for j in range(len(n1)):
            if n1[j] >= min_points and n2[j] >= min_points:
                bins.append(ProfileBin(gi, float(lo + (j + 0.5) * bin_m), int(n1[j]), int(n2[j]), float(m1[j]),
                                       float(m2[j]), float(s1[j]), float(s2[j])))
    return SpanProfile(tuple(bins), origin, axis, up_v, offsets, float(bin_m), float(half_width_m), float(band_m))

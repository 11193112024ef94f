"""Span profile: the height change of the deck underside per bin along each girder line, between two epochs.

Points are given in *span coordinates*: station along the bridge (``s``), lateral offset (``l``) and height
along the deck normal (``h``), metres. A point counts for a girder line only when it lies on the deck
underside: its local surface normal (a plane fitted to the points of its 20 cm voxel) is within ``max_tilt_deg`` of the deck
normal, it lies within ``band_m`` of the underside level through the line's targets, and its lateral offset is
inside the underside's own lateral extent by ``edge_margin_m``. The lowest centimetres of a side face the
scanner sees have horizontal normals and lie outside that extent: neither test lets them in.

In each bin one plane ``h = a_e + b (s - s_c) + c (l - l_g)`` with an intercept per epoch is fitted to both
epochs' selected points (3.5-MAD rejection), so each height is the underside's at the bin centre on the girder
line whatever the two scans' point distributions inside the bin. The change's σ combines both fits and both epochs' registration
errors at that place (:class:`RegistrationSigma`).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from common.arrays import median_and_sigma
from registration.errors import InputError

#: Voxel edge of the local planes that give each point its normal (metres).
VOXEL_M = 0.2


@dataclass(frozen=True)
class RegistrationSigma:
    """Uncertainty of one epoch's registration into the common frame.

    Attributes
    ----------
    sigma_translation_m : float
        Standard deviation of the translation at the pivot (the tie points' centroid), metres.
    sigma_rotation_rad : float
        Standard deviation of the rotation, radians.
    pivot_sl : (2,) tuple of float
        Station and lateral offset of the pivot, metres.
    """

    sigma_translation_m: float
    sigma_rotation_rad: float
    pivot_sl: tuple[float, float]

    def vertical_m(self, s_m: np.ndarray, l_m: np.ndarray) -> np.ndarray:
        """(K,) vertical σ of the registration at stations ``s_m`` and offsets ``l_m``: σ_t ⊕ lever x σ_rot."""
        lever = np.hypot(np.asarray(s_m, dtype=np.float64) - self.pivot_sl[0],
                         np.asarray(l_m, dtype=np.float64) - self.pivot_sl[1])
        return np.hypot(self.sigma_translation_m, lever * self.sigma_rotation_rad)


@dataclass(frozen=True)
class GirderLine:
    """A girder line of the layout: its lateral offset and the underside level along it.

    Attributes
    ----------
    offset_m : float
        Lateral offset of the line (span coordinates), metres.
    target_s_m, target_h_m : tuple of float
        Stations and heights of the line's targets (they sit on the underside), metres.
    """

    offset_m: float
    target_s_m: tuple[float, ...]
    target_h_m: tuple[float, ...]

    def underside_h(self, s_m: np.ndarray) -> np.ndarray:
        """Underside level at stations ``s_m``: a line through the targets (their mean for one target)."""
        s_t, h_t = np.asarray(self.target_s_m), np.asarray(self.target_h_m)
        if len(s_t) >= 2 and np.ptp(s_t) > 1.0:
            return np.polyval(np.polyfit(s_t, h_t, 1), s_m)
        return np.full(np.shape(s_m), float(h_t.mean()))


@dataclass(frozen=True)
class ProfileBin:
    """One bin of one girder line (heights in metres, σ of the fitted heights included)."""

    girder: int
    station_m: float
    n_from: int
    n_to: int
    height_from_m: float
    height_to_m: float
    sigma_fit_m: float
    std_from_m: float
    std_to_m: float
    sigma_registration_m: float

    @property
    def change_m(self) -> float:
        return self.height_to_m - self.height_from_m

    @property
    def sigma_change_m(self) -> float:
        """σ of the change: the joint fit of both epochs' heights and both registrations."""
        return float(np.hypot(self.sigma_fit_m, self.sigma_registration_m))


@dataclass(frozen=True, eq=False)
class SpanProfile:
    """Result of :func:`span_profile`.

    Attributes
    ----------
    bins : tuple of ProfileBin
    girders : tuple of GirderLine
    bin_m, half_width_m, band_m, max_tilt_deg : float
        Parameters used.
    underside_extent_m : (2,) tuple of float
        Lateral extent of the underside found in the scans (both epochs), metres.
    notes : tuple of str
        Girder lines or bins left out, and why.
    """

    bins: tuple[ProfileBin, ...]
    girders: tuple[GirderLine, ...]
    bin_m: float
    half_width_m: float
    band_m: float
    max_tilt_deg: float
    underside_extent_m: tuple[float, float]
    notes: tuple[str, ...] = ()

    @property
    def girder_offsets_m(self) -> tuple[float, ...]:
        return tuple(g.offset_m for g in self.girders)

    def girder_of(self, l_m: np.ndarray) -> np.ndarray:
        """(K,) index of the girder line nearest each lateral offset."""
        l_m = np.atleast_1d(np.asarray(l_m, dtype=np.float64))
        return np.argmin(np.abs(l_m[:, None] - np.asarray(self.girder_offsets_m)[None, :]), axis=1)

    def table(self) -> list[dict]:
        """One JSON-ready row per bin (girders counted from 1, heights in m, the rest in mm)."""
        return [{"girder": b.girder + 1, "station_m": round(b.station_m, 3), "n_from": b.n_from, "n_to": b.n_to,
                 "height_from_m": b.height_from_m, "height_to_m": b.height_to_m,
                 "std_from_mm": b.std_from_m * 1e3, "std_to_mm": b.std_to_m * 1e3,
                 "change_mm": b.change_m * 1e3, "sigma_change_mm": b.sigma_change_m * 1e3,
                 "sigma_fit_mm": b.sigma_fit_m * 1e3,
                 "sigma_registration_mm": b.sigma_registration_m * 1e3} for b in self.bins]


def voxel_normals(xyz: np.ndarray, *, voxel_m: float = VOXEL_M, min_points: int = 6) -> np.ndarray:
    """(N, 3) unit normal of the plane fitted to the points of each point's voxel (sign arbitrary).

    Parameters
    ----------
    xyz : (N, 3) float64 array, metres
    voxel_m : float, keyword-only
        Edge of the cubic voxels (default 0.2 m: several coarse-scan points across, far less than a deck).
    min_points : int, keyword-only
        Voxels with fewer points give NaN normals (default 6).

    Returns
    -------
    (N, 3) float64 array

    Notes
    -----
    One pass of ``np.bincount`` accumulates each voxel's moments, so the cost is a few passes over the
    points plus a 3x3 eigen-decomposition per voxel, where a neighbour search per point costs seconds.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    n = len(xyz)
    out = np.full((n, 3), np.nan)
    if n == 0:
        return out
    p = xyz - xyz.min(axis=0)
    cell = np.floor(p / voxel_m).astype(np.int64)
    _, inv, counts = np.unique(cell[:, 0] * 4_000_037 * 4_000_037 + cell[:, 1] * 4_000_037 + cell[:, 2],
                               return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    m = len(counts)
    local = p - cell * voxel_m  # small numbers: the moments keep their precision
    mean = np.column_stack([np.bincount(inv, local[:, k], m) for k in range(3)]) / counts[:, None]
    d = local - mean[inv]
    cov = np.empty((m, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = np.bincount(inv, d[:, i] * d[:, j], m)
    ok = counts >= min_points
    normals = np.full((m, 3), np.nan)
    if ok.any():
        _, vec = np.linalg.eigh(cov[ok])
        normals[ok] = vec[:, :, 0]
    out[:] = normals[inv]
    return out


def underside_points(slh: np.ndarray, girders: Sequence[GirderLine], *, band_m: float, half_width_m: float,
                      max_tilt_deg: float) -> np.ndarray:
    """(N,) bool: points near the underside level of some girder line whose local normal is the deck normal.

    Parameters
    ----------
    slh : (N, 3) float64 array
        Points in span coordinates (station, lateral offset, height), metres.
    girders : sequence of GirderLine
    band_m, half_width_m, max_tilt_deg : float, keyword-only
        Height band about each line's underside level, lateral reach (the extent is measured 0.5 m
        beyond it), and the largest angle between a point's local normal and the deck normal.

    Returns
    -------
    (N,) bool array
    """
    near = np.zeros(len(slh), bool)
    for g in girders:
        lat = np.abs(slh[:, 1] - g.offset_m) <= half_width_m + 0.5
        near[lat] |= np.abs(slh[lat, 2] - g.underside_h(slh[lat, 0])) <= band_m
    idx = np.flatnonzero(near)
    normals = voxel_normals(slh[idx])
    with np.errstate(invalid="ignore"):
        flat = np.abs(normals[:, 2]) >= np.cos(np.radians(max_tilt_deg))
    out = np.zeros(len(slh), bool)
    out[idx[flat]] = True
    return out


def _joint_fit(ds: tuple[np.ndarray, np.ndarray], dl: tuple[np.ndarray, np.ndarray],
               h: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Both epochs' underside heights at (0, 0) from one fit with the bin's slopes shared.

    ``h = a_e + b ds + c dl (+ d ds in the second epoch)``: the underside's geometry (gradient, cross-fall) is
    common to the two epochs, so each epoch's height at the bin centre does not depend on where its points
    lie in the bin; the slope change ``d`` (the deformation's) is fitted where both epochs cover at least half
    the bin. Weighted by each epoch's residual variance, with one pass of 3.5-MAD rejection per epoch.

    Returns (heights (2,), their covariance (2, 2), residual stds (2,), points kept (2,)), or None.
    """
    span = [np.ptp(d) if len(d) else 0.0 for d in ds]
    both = min(span) >= 0.5 * max(np.ptp(np.concatenate(ds)), 1e-9)
    e = np.concatenate([np.zeros(len(ds[0])), np.ones(len(ds[1]))])
    s_all, l_all, h_all = np.concatenate(ds), np.concatenate(dl), np.concatenate(h)
    cols = [1.0 - e, e, s_all, l_all] + ([s_all * e] if both else [])
    a = np.column_stack(cols)
    keep = np.ones(len(h_all), bool)
    w = np.ones(len(h_all))
    std = np.ones(2)
    for _ in range(3):
        k0, k1 = keep & (e == 0), keep & (e == 1)
        if k0.sum() < 5 or k1.sum() < 5:
            return None
        sw = np.sqrt(w[keep])
        coef, *_ = np.linalg.lstsq(a[keep] * sw[:, None], h_all[keep] * sw, rcond=None)
        res = h_all - a @ coef
        new = np.zeros(len(h_all), bool)
        for k, sel in enumerate((e == 0, e == 1)):
            r = res[sel & keep]
            std[k] = max(float(np.sqrt(np.mean(r ** 2))), 1e-6)
            mad = median_and_sigma(r)[1]
            new[sel] = np.abs(res[sel]) <= max(3.5 * mad, 1e-5)
        w = np.where(e == 0, 1.0 / std[0] ** 2, 1.0 / std[1] ** 2)
        if np.array_equal(new, keep):
            break
        keep = new
    ak = a[keep]
    try:
        cov = np.linalg.inv(ak.T @ (ak * w[keep][:, None]))
    except np.linalg.LinAlgError:
        return None
    coef = cov @ (ak.T @ (h_all[keep] * w[keep]))
    n = np.array([int(np.sum(keep & (e == 0))), int(np.sum(keep & (e == 1)))])
    return coef[:2], cov[:2, :2], std, n


def span_profile(slh_from: np.ndarray, slh_to: np.ndarray, girders: Sequence[GirderLine], *,
                 stations_m: tuple[float, float], bin_m: float = 2.5, half_width_m: float = 0.5,
                 band_m: float = 0.15, max_tilt_deg: float = 15.0, edge_margin_m: float = 0.1,
                 registration: tuple[RegistrationSigma | None, RegistrationSigma | None] = (None, None),
                 min_points: int = 10) -> SpanProfile:
    """Height change of the deck underside per bin along each girder line, with its σ.

    Parameters
    ----------
    slh_from, slh_to : (N, 3), (M, 3) float64 arrays, metres
        The two epochs' points in span coordinates (station, lateral offset, height along the deck normal),
        both registered into the same frame.
    girders : sequence of GirderLine
        The layout's girder lines (lateral offsets more than ``2 * half_width_m`` apart).
    stations_m : (2,) tuple of float, keyword-only
        Stations covered (e.g. from the first pier to the last); bins start at multiples of ``bin_m``.
    bin_m : float, keyword-only
        Bin length along the span (default 2.5 m, as the dissertation's whole-bridge comparison).
    half_width_m : float, keyword-only
        Points within this lateral distance of a girder line are used (default 0.5 m) ...
    band_m : float, keyword-only
        ... within this distance of the underside level through the line's targets (default 0.15 m) ...
    max_tilt_deg : float, keyword-only
        ... whose local normal is within this angle of the deck normal (default 15 degrees) ...
    edge_margin_m : float, keyword-only
        ... and at least this far inside the lateral extent of such points (default 0.1 m).
    registration : (2,) tuple of RegistrationSigma or None, keyword-only
        Each epoch's registration uncertainty (None: the epoch defines the frame).
    min_points : int, keyword-only
        Bins with fewer selected points in either epoch are left out (default 10).

    Returns
    -------
    SpanProfile
    """
    a = _check(slh_from, "first epoch")
    b = _check(slh_to, "second epoch")
    if not girders:
        raise InputError("a span profile needs at least one girder line (measurement targets in the layout)")
    if not (bin_m > 0 and half_width_m > 0 and band_m > 0 and 0 < max_tilt_deg < 90 and edge_margin_m >= 0):
        raise InputError("span profile: bin length, half width and band must be positive, the tilt in (0, 90) degrees")
    lo = np.floor(stations_m[0] / bin_m) * bin_m
    nb = max(1, int(np.ceil((stations_m[1] - lo) / bin_m - 1e-9)))
    picked, extents = [], []
    for xyz in (a, b):
        inside = (xyz[:, 0] >= lo) & (xyz[:, 0] < lo + nb * bin_m)
        pts = xyz[inside]
        sel = underside_points(pts, girders, band_m=band_m, half_width_m=half_width_m, max_tilt_deg=max_tilt_deg)
        picked.append(pts[sel])
        if sel.sum() >= 20:
            extents.append(np.percentile(pts[sel, 1], [0.1, 99.9]))
    if not extents:
        return SpanProfile((), tuple(girders), float(bin_m), float(half_width_m), float(band_m), float(max_tilt_deg),
                           (float("nan"), float("nan")), ("no deck underside points found in either scan",))
    edge_lo = max(e[0] for e in extents) + edge_margin_m
    edge_hi = min(e[1] for e in extents) - edge_margin_m
    bins, notes = [], []
    for gi, g in enumerate(girders):
        l_lo, l_hi = max(g.offset_m - half_width_m, edge_lo), min(g.offset_m + half_width_m, edge_hi)
        if l_hi - l_lo < 0.1:
            notes.append(f"girder line {gi + 1} (offset {g.offset_m:+.2f} m) lies at the edge of the underside seen; "
                         "left out")
            continue
        fits = []
        for pts in picked:
            on = (pts[:, 1] >= l_lo) & (pts[:, 1] <= l_hi)
            p = pts[on]
            k = np.floor((p[:, 0] - lo) / bin_m).astype(np.int64)
            order = np.argsort(k, kind="stable")
            p, k = p[order], k[order]
            cuts = np.searchsorted(k, np.arange(nb + 1))
            fits.append([(p[cuts[j]:cuts[j + 1]]) for j in range(nb)])
        for j in range(nb):
            s_c = lo + (j + 0.5) * bin_m
            pa, pb = fits[0][j], fits[1][j]
            if len(pa) < min_points or len(pb) < min_points:
                continue
            fit = _joint_fit((pa[:, 0] - s_c, pb[:, 0] - s_c), (pa[:, 1] - g.offset_m, pb[:, 1] - g.offset_m),
                             (pa[:, 2], pb[:, 2]))
            if fit is None or min(fit[3]) < min_points:
                continue
            heights, cov, std, n = fit
            sig_reg = float(np.sqrt(sum(float(r.vertical_m(np.array([s_c]), np.array([g.offset_m]))[0]) ** 2
                                        for r in registration if r is not None)))
            sig_fit = float(np.sqrt(max(cov[0, 0] + cov[1, 1] - 2 * cov[0, 1], 0.0)))
            bins.append(ProfileBin(gi, float(s_c), int(n[0]), int(n[1]), float(heights[0]), float(heights[1]),
                                   sig_fit, float(std[0]), float(std[1]), sig_reg))
    return SpanProfile(tuple(bins), tuple(girders), float(bin_m), float(half_width_m), float(band_m),
                       float(max_tilt_deg), (float(edge_lo - edge_margin_m), float(edge_hi + edge_margin_m)),
                       tuple(notes))


def _check(a, what: str) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"span profile: the {what}'s points must be an (N, 3) array")
    return a[np.all(np.isfinite(a), axis=1)]


def girder_lines(target_sl_m: np.ndarray, target_h_m: np.ndarray, *, min_separation_m: float = 1.0
                 ) -> tuple[GirderLine, ...]:
    """Group targets into girder lines by their lateral offsets (more than ``min_separation_m`` apart).

    Parameters
    ----------
    target_sl_m : (K, 2) array
        Station and lateral offset of each measurement target (from the layout), metres.
    target_h_m : (K,) array
        Each target's height in the epoch the band is drawn around (NaN where not measured), metres.
    min_separation_m : float, keyword-only
        Targets closer than this laterally share a line (default 1 m).

    Returns
    -------
    tuple of GirderLine, by increasing offset; lines without a measured height are left out.
    """
    sl = np.asarray(target_sl_m, dtype=np.float64).reshape(-1, 2)
    h = np.asarray(target_h_m, dtype=np.float64).reshape(-1)
    if len(sl) == 0:
        return ()
    order = np.argsort(sl[:, 1])
    groups = [[order[0]]]
    for k in order[1:]:
        if sl[k, 1] - sl[groups[-1][-1], 1] > min_separation_m:
            groups.append([k])
        else:
            groups[-1].append(k)
    out = []
    for grp in groups:
        ok = [k for k in grp if np.isfinite(h[k])]
        if ok:
            out.append(GirderLine(float(sl[grp, 1].mean()), tuple(float(sl[k, 0]) for k in ok),
                                  tuple(float(h[k]) for k in ok)))
    return tuple(out)

"""A second, guided look at the targets the blob search missed: small and grazing targets.

A 50 mm disc seen at 70-80 deg incidence from 20 m spans less than one cell of a 0.05-0.08 deg
coarse scan: at most a cell or two are partly lit, dimmer than the global threshold. Once the
identification has placed the layout in the scanner frame, each missing target's direction is
known to a few centimetres, so the map is searched only there, with a local test: the brightest
cell near the predicted direction must stand well above its own neighbourhood and lie at the
predicted range. A cell that passes becomes a detection of that target (its window is then
planned from the coarse scan, not from the layout).

On an intensity scale whose top is a receiver's ceiling (raw amplitude, dB), a clipped target
and its surroundings may both lie below a threshold made for the whole map, or the threshold
above the top: the rise asked of a peak is then at most half the room between the local
background and the map's top. A target that stays missing gets its reason
(:func:`missing_reasons`): outside the scan, hidden behind something nearer, seen through,
its surroundings at the ceiling, not brighter than its surroundings, or bright at another range.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from common.arrays import median_and_sigma
from lidar.angles import spherical_from_xyz
from lidar.detection import Detection, DetectionResult
from lidar.identification import Identification
from lidar.reflectance_map import ReflectanceMap

MIN_CONTRAST = 0.5  # the peak must rise at least half-way from the local background to the global threshold
MIN_MAD_FACTOR = 8.0  # and at least this many local robust standard deviations
MIN_RISE = 0.05  # and at least this much (normalised intensity)
#: A background this close to the map's top leaves no room for a target to stand out (the surface reads clipped).
MIN_ROOM = MIN_RISE


def map_top(rmap: ReflectanceMap) -> float:
    """The map's brightest cell (the top of its intensity scale in practice: the receiver's ceiling)."""
    a = rmap.max_intensity
    top = float(np.fmax.reduce(a, axis=None)) if a.size else float("nan")
    return top if np.isfinite(top) else 1.0


def needed_rise(bg: float, mad: float, threshold: float, top: float) -> float:
    """How far above its local background ``bg`` a peak must rise to be a target (see the module text)."""
    rise = MIN_CONTRAST * (threshold - bg)
    if top - bg >= MIN_ROOM:  # a clipped target on a bright surface: half the room to the top is enough
        rise = min(rise, 0.5 * (top - bg))
    return max(rise, MIN_MAD_FACTOR * mad, MIN_RISE)  # never within the local noise


def stands_out(peak: float, bg: float, mad: float, threshold: float, top: float) -> bool:
    """Whether a peak is a target against its local background ``bg`` (robust sigma ``mad``).

    It rises by :func:`needed_rise`, or it reads at the scale's top (clipped) with room (``MIN_ROOM`` and six
    local sigma) between the top and the background.
    """
    if peak >= bg + needed_rise(bg, mad, threshold, top):
        return True
    return peak >= top - 1e-3 and top - bg >= max(MIN_ROOM, 6.0 * mad)


def _patch(rmap: ReflectanceMap, row: float, col: float, half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    h, w = rmap.shape
    r0, c0 = int(round(row)), int(round(col))
    rows = np.arange(r0 - half, r0 + half + 1)
    cols = np.arange(c0 - half, c0 + half + 1)
    rows = rows[(rows >= 0) & (rows < h)]
    cols = np.mod(cols, w) if rmap.full_circle else cols[(cols >= 0) & (cols < w)]
    if rows.size == 0 or cols.size == 0:
        return rows, cols, np.empty((0, 0), dtype=np.float32)
    return rows, cols, rmap.max_intensity[np.ix_(rows, cols)]


def bright_near(rmap: ReflectanceMap, xyz_socs: np.ndarray, threshold: float, *, tolerance_m: float = 0.15,
                range_tolerance_m: float = 0.3, top: float | None = None) -> bool | None:
    """Whether the map shows a target where one is predicted: True (a local peak at the range), False, None.

    None when the map cannot tell (the direction is outside it, or it holds no return there). ``top``: the
    map's top (:func:`map_top`, computed when not given).
    """
    xyz = np.asarray(xyz_socs, dtype=np.float64)
    theta, phi, rng = spherical_from_xyz(xyz[None])
    r = float(rng[0])
    if not r > 0.5:
        return None
    row, col = rmap.cells_of(theta, phi)
    if not (0 <= row[0] < rmap.shape[0]) or (not rmap.full_circle and not 0 <= col[0] < rmap.shape[1]):
        return None
    k = max(2, int(math.ceil(math.degrees(tolerance_m / r) / rmap.step_deg)) + 1)
    rows, cols, near = _patch(rmap, row[0], col[0], k)
    _, _, wide = _patch(rmap, row[0], col[0], 3 * k)
    if near.size == 0 or not np.any(np.isfinite(near)):
        return None
    bg, mad = median_and_sigma(wide, skip_nan=True)
    a, b = (int(v) for v in np.unravel_index(int(np.nanargmax(near)), near.shape))
    if not stands_out(float(near[a, b]), bg, mad, threshold, map_top(rmap) if top is None else top):
        return False
    cell_range = float(rmap.range_m[rows[a], cols[b]])
    return bool(np.isfinite(cell_range) and abs(cell_range - r) <= range_tolerance_m + tolerance_m)


def seen_through(rmap: ReflectanceMap, xyz_socs: np.ndarray, *, margin_m: float = 1.0) -> bool | None:
    """Whether the scan looked straight through a position: nothing there, only farther surfaces (or none).

    True when every cell around the position's direction returned from beyond it (by ``margin_m``) or held
    no return at all, inside the scanned area; False when something returned at or before it; None
    outside the map. A target predicted where the scan saw through cannot be there.
    """
    xyz = np.asarray(xyz_socs, dtype=np.float64)
    theta, phi, rng = spherical_from_xyz(xyz[None])
    r = float(rng[0])
    if not r > 0.5:
        return None
    row, col = rmap.cells_of(theta, phi)
    if not (1 <= row[0] < rmap.shape[0] - 1) or (not rmap.full_circle and not 1 <= col[0] < rmap.shape[1] - 1):
        return None
    ranges = _patch_ranges(rmap, row[0], col[0], 1)
    if ranges.size == 0:
        return None
    return bool(np.all(~np.isfinite(ranges) | (ranges > r + margin_m)))


def _patch_ranges(rmap: ReflectanceMap, row: float, col: float, half: int) -> np.ndarray:
    h, w = rmap.shape
    r0, c0 = int(round(row)), int(round(col))
    rows = np.arange(r0 - half, r0 + half + 1)
    cols = np.arange(c0 - half, c0 + half + 1)
    rows = rows[(rows >= 0) & (rows < h)]
    cols = np.mod(cols, w) if rmap.full_circle else cols[(cols >= 0) & (cols < w)]
    return rmap.range_m[np.ix_(rows, cols)] if rows.size and cols.size else np.empty((0, 0), np.float32)


def recover_predicted(rmap: ReflectanceMap, detections: DetectionResult, identification: Identification, *,
                      tolerance_m: float = 0.15, range_tolerance_m: float = 0.3
                      ) -> tuple[DetectionResult, Identification]:
    """Detections and identification with the missing targets found by a guided look where possible.

    Parameters
    ----------
    rmap : ReflectanceMap
    detections : DetectionResult
    identification : Identification
        Its predicted matches (``detection is None``) are searched for.
    tolerance_m : float, keyword-only
        How far from its predicted position a target may be found. Default 0.15 m.
    range_tolerance_m : float, keyword-only
        How far the cell's range may be from the predicted range. Default 0.3 m.

    Returns
    -------
    (DetectionResult, Identification)
        The inputs with one guided detection appended per recovered target.
    """
    dets = list(detections.detections)
    matches = list(identification.matches)
    changed = False
    top = map_top(rmap) if any(m.predicted for m in matches) else 1.0
    for i, m in enumerate(matches):
        if not m.predicted:
            continue
        xyz = np.asarray(m.xyz_socs, dtype=np.float64)
        theta, phi, rng = spherical_from_xyz(xyz[None])
        r = float(rng[0])
        if not r > 0.5:
            continue
        row, col = rmap.cells_of(theta, phi)
        k = max(2, int(math.ceil(math.degrees(tolerance_m / r) / rmap.step_deg)) + 1)
        rows, cols, near = _patch(rmap, row[0], col[0], k)
        _, _, wide = _patch(rmap, row[0], col[0], 3 * k)
        if near.size == 0 or not np.any(np.isfinite(near)):
            continue
        bg, mad = median_and_sigma(wide, skip_nan=True)
        a, b = (int(v) for v in np.unravel_index(int(np.nanargmax(near)), near.shape))
        peak = float(near[a, b])
        if not stands_out(peak, bg, mad, detections.threshold, top):
            continue
        rr, cc = rows[a], cols[b]
        cell_range = float(rmap.range_m[rr, cc])
        if not (np.isfinite(cell_range) and abs(cell_range - r) <= range_tolerance_m + tolerance_m):
            continue
        # intensity-weighted centre of the lit cells around the peak
        ra = np.arange(max(a - 1, 0), min(a + 2, near.shape[0]))
        ca = np.arange(max(b - 1, 0), min(b + 2, near.shape[1]))
        blk = near[np.ix_(ra, ca)]
        wgt = np.where(np.isfinite(blk), np.clip(blk - (bg + 0.5 * (peak - bg)), 0, None), 0.0)
        if wgt.sum() <= 0:
            wgt = np.where(blk == peak, 1.0, 0.0)
        rr_f = float((wgt.sum(axis=1) @ rows[ra].astype(float)) / wgt.sum())
        cc_unwrapped = cols[ca].astype(float)
        if rmap.full_circle:  # keep the column indices continuous across the seam
            cc_unwrapped = cc_unwrapped + np.where(cc_unwrapped - cols[b] > rmap.shape[1] / 2, -rmap.shape[1], 0) \
                + np.where(cols[b] - cc_unwrapped > rmap.shape[1] / 2, rmap.shape[1], 0)
        cc_f = float((wgt.sum(axis=0) @ cc_unwrapped) / wgt.sum())
        t_c, p_c = rmap.cell_angles(rr_f, cc_f)
        pos = rmap.xyz_of(float(t_c), float(p_c), cell_range)
        if float(np.linalg.norm(pos - xyz)) > tolerance_m:
            continue
        dets.append(Detection(theta_deg=float(t_c), phi_deg=float(p_c), range_m=cell_range,
                              xyz_socs=tuple(float(v) for v in pos), peak_intensity=peak,
                              n_cells=int(np.count_nonzero(wgt)), size_deg=rmap.step_deg,
                              expected_size_deg=float(math.degrees(0.05 / cell_range)),
                              score=float(min(1.0, peak)) * 0.5, guided=True))
        matches[i] = replace(m, xyz_socs=tuple(float(v) for v in pos), detection=len(dets) - 1,
                             residual_m=float(np.linalg.norm(pos - xyz)))
        changed = True
    if not changed:
        return detections, identification
    return replace(detections, detections=tuple(dets)), replace(identification, matches=tuple(matches))


def missing_reasons(rmap: ReflectanceMap, detections: DetectionResult, identification: Identification, *,
                    tolerance_m: float = 0.15, range_tolerance_m: float = 0.3) -> dict[str, str]:
    """Why each target the coarse scan did not find (a predicted match) stayed missing, in a few words.

    Parameters
    ----------
    rmap, detections, identification
        The coarse analysis after :func:`recover_predicted`.
    tolerance_m, range_tolerance_m : float, keyword-only
        As :func:`recover_predicted`'s. Defaults 0.15 m and 0.3 m.

    Returns
    -------
    dict
        Target id -> reason, for every predicted match: outside the coarse scan; hidden behind something nearer;
        the scan saw through its place; no return there; its surroundings read at the intensity ceiling;
        not brighter than its surroundings (the peak and the rise it needed); bright at another range.
    """
    out: dict[str, str] = {}
    top = map_top(rmap) if identification.missing else 1.0
    for m in identification.matches:
        if not m.predicted:
            continue
        xyz = np.asarray(m.xyz_socs, dtype=np.float64)
        theta, phi, rng = spherical_from_xyz(xyz[None])
        r = float(rng[0])
        row, col = rmap.cells_of(theta, phi)
        inside = 0 <= row[0] < rmap.shape[0] and (rmap.full_circle or 0 <= col[0] < rmap.shape[1])
        if not r > 0.5 or not inside:
            out[m.id] = "outside the coarse scan"
            continue
        k = max(2, int(math.ceil(math.degrees(tolerance_m / r) / rmap.step_deg)) + 1)
        centre = _patch_ranges(rmap, row[0], col[0], 1)
        if centre.size and np.all(np.isfinite(centre)) and np.all(centre < r - range_tolerance_m - tolerance_m):
            out[m.id] = f"hidden behind something {r - float(np.median(centre)):.1f} m in front of it"
            continue
        if seen_through(rmap, xyz):
            out[m.id] = "the scan saw through its place (fallen off, or the layout is wrong there)"
            continue
        rows, cols, near = _patch(rmap, row[0], col[0], k)
        if near.size == 0 or not np.any(np.isfinite(near)):
            out[m.id] = "no return where it should be"
            continue
        _, _, wide = _patch(rmap, row[0], col[0], 3 * k)
        bg, mad = median_and_sigma(wide, skip_nan=True)
        a, b = (int(v) for v in np.unravel_index(int(np.nanargmax(near)), near.shape))
        peak = float(near[a, b])
        if top - bg < MIN_ROOM:
            out[m.id] = f"the surface around it reads at the intensity ceiling ({bg:.2f} of {top:.2f}): no contrast"
            continue
        need = needed_rise(bg, mad, detections.threshold, top)
        if not stands_out(peak, bg, mad, detections.threshold, top):
            out[m.id] = f"not brighter than its surroundings (peak {peak:.2f}, background {bg:.2f}, needs {bg + need:.2f})"
            continue
        cell_range = float(rmap.range_m[rows[a], cols[b]])
        out[m.id] = f"a bright spot there lies at {cell_range:.1f} m, not at the predicted {r:.1f} m"
    return out


def missing_note(reasons: dict[str, str], n_targets: int) -> str | None:
    """One line naming the targets the coarse scan did not find and why (None when none is missing)."""
    if not reasons:
        return None
    parts = [f"{tid} ({why})" for tid, why in reasons.items()]
    return (f"the coarse scan did not find {len(reasons)} of {n_targets} target(s); their windows come from the "
            f"layout: {'; '.join(parts)}")

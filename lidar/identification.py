"""Identification of detected reflectors against the campaign layout.

Only rigid-invariant geometry is used: congruent triangles of pairwise
distances propose a correspondence, a rigid fit (Kabsch) scores it by the
number of layout reflectors it explains, and the best one is refined on all
matches. The layout may be in any frame (design drawings, a total station).
Unmatched detections and layout reflectors without a detection are reported;
the latter get a position predicted from the fit, marked as predicted.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linear_sum_assignment

from common.errors import InputError, ProcessingError
from lidar.layout import Layout
from common.rigid import Transform, fit_rigid, pairwise_distances


@dataclass(frozen=True)
class TargetMatch:
    """One layout reflector in this scan.

    ``detection`` is the index of the matched detection, or None when the
    position is ``predicted`` from the layout fit (not resolved or not seen).
    """

    id: str
    group: str
    xyz_socs: tuple[float, ...]
    detection: Optional[int]
    residual_m: Optional[float]

    @property
    def predicted(self) -> bool:
        return self.detection is None


@dataclass(frozen=True, eq=False)
class Identification:
    """Result of matching detections to the layout.

    Attributes
    ----------
    matches : tuple of TargetMatch, in layout order
    rotation, translation : layout frame -> scanner frame
    rms_m : float
        RMS residual of the matched reflectors after the fit.
    extra_detections : tuple of int
        Detections that match no layout reflector (other bright objects).
    tilt_deg : float
        Angle between the layout's up axis carried into the scanner frame and
        the scanner's +z: how far from level the solution puts the scanner.
    """

    matches: tuple[TargetMatch, ...]
    rotation: np.ndarray
    translation: np.ndarray
    rms_m: float
    extra_detections: tuple[int, ...]
    tilt_deg: float = float("nan")

    @property
    def missing(self) -> tuple[str, ...]:
        return tuple(m.id for m in self.matches if m.predicted)

    def match(self, reflector_id: str) -> TargetMatch:
        for m in self.matches:
            if m.id == reflector_id:
                return m
        raise InputError(f"unknown reflector {reflector_id!r}")


def _seed_triangles(xyz: np.ndarray, limit: int, groups: Optional[tuple] = None) -> list[tuple[int, int, int]]:
    """Well-conditioned layout triangles (large, not thin), best first.

    The pier (reference) targets' own triangles always come first, since deck targets are the ones a coarse scan misses.
    """
    n = len(xyz)
    scored = []
    for a, b, c in combinations(range(n), 3):
        ab, ac = xyz[b] - xyz[a], xyz[c] - xyz[a]
        area = 0.5 * np.linalg.norm(np.cross(ab, ac))
        per = np.linalg.norm(ab) + np.linalg.norm(ac) + np.linalg.norm(xyz[c] - xyz[b])
        if per > 0:
            scored.append((area / per ** 2, (a, b, c)))
    scored.sort(key=lambda s: -s[0])
    # spread the seeds over many reflectors so a few missing ones cannot spoil all of them
    out: list[tuple[int, int, int]] = []
    used: dict[int, int] = {}
    for _, tri in scored:
        if all(used.get(k, 0) < max(3, limit // max(n, 1) + 1) for k in tri):
            out.append(tri)
            for k in tri:
                used[k] = used.get(k, 0) + 1
        if len(out) >= limit:
            break
    if groups is not None:
        refs = [tri for _, tri in scored if all(groups[k] == "reference" for k in tri)][:max(4, limit // 4)]
        out = refs + [tri for tri in out if tri not in refs]
    return out


def _assign(pred: np.ndarray, det: np.ndarray, tol: float) -> list[tuple[int, int, float]]:
    """Unique layout->detection pairs closer than ``tol`` (optimal assignment)."""
    d = np.linalg.norm(pred[:, None, :] - det[None, :, :], axis=2)
    cost = np.where(d <= tol, d, 1e6)
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c), float(d[r, c])) for r, c in zip(rows, cols) if d[r, c] <= tol]


#: Default largest scanner tilt a solution may imply and still count as levelled (degrees). Compensators
#: hold a levelled scanner to hundredths of a degree; the rest is the layout's few centimetres of error.
MAX_TILT_DEG = 2.0


#: Seeds tried after a perfect levelled solution, to find an equally good rival.
TIE_SEEDS = 6


def _rival(best, candidates: dict) -> Optional[str]:
    """Describe another levelled solution as good as the best one (a different assignment), or None."""
    (lev, count, neg_sum), _, _ = best
    best_key = next(k for k, v in candidates.items() if v[0] == best[0])
    for key, ((lev2, count2, neg_sum2), _, _) in candidates.items():
        if key == best_key or lev2 != lev or count2 != count:
            continue
        if -neg_sum2 <= -neg_sum * 1.5 + 0.01 * count:
            swapped = sorted(set(key) - set(best_key))
            return f"{len(swapped)} reflector(s) would be assigned differently"
    return None


def tilt_deg(rotation: np.ndarray, up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> float:
    """Angle (degrees) between the layout's up axis, rotated into the scanner frame, and the scanner's +z.

    >>> round(tilt_deg(np.eye(3)), 6)
    0.0
    >>> round(tilt_deg(np.diag([1.0, -1.0, -1.0])), 6)  # upside down
    180.0
    """
    up = np.asarray(up_layout, dtype=np.float64)
    v = np.asarray(rotation) @ (up / np.linalg.norm(up))
    return float(np.degrees(np.arccos(np.clip(v[2], -1.0, 1.0))))


def identify_reflectors(detections_xyz: np.ndarray, layout: Layout, *, tolerance_m: float = 0.15,
                        max_seeds: int = 60, max_tilt_deg: Optional[float] = MAX_TILT_DEG,
                        up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> Identification:
    """Match detections (scanner frame) to the layout (any frame).

    Parameters
    ----------
    detections_xyz : (M, 3) float64 array
        Approximate detection positions in the scanner frame, metres.
    layout : Layout
    tolerance_m : float, keyword-only
        How far apart matched distances and positions may be (layout accuracy
        plus detection accuracy). Default 0.15 m.
    max_seeds : int, keyword-only
        Layout triangles tried as seeds. Default 60.
    max_tilt_deg : float or None, keyword-only
        Terrestrial scanners are levelled: a solution implying a tilt beyond
        this (default 2 degrees) loses against any levelled one, however well
        it fits. This breaks the mirror ambiguity of coplanar, symmetric
        reference targets (a 180-degree turn about an axis in their plane fits
        them exactly as well). None for set-ups without a compensator.
    up_layout : (3,) sequence, keyword-only
        The layout's up axis (default +z).

    Returns
    -------
    Identification

    Raises
    ------
    ProcessingError
        Fewer than 3 detections, or no three detections congruent with the layout.
    """
    det = np.asarray(detections_xyz, dtype=np.float64).reshape(-1, 3)
    lay = layout.xyz
    if not np.all(np.isfinite(det)):
        raise InputError("detection positions must be finite")
    if len(det) < 3:
        raise ProcessingError(f"only {len(det)} reflector(s) detected; at least 3 are needed to identify them "
                              "(check the coarse scan covers the bridge, or lower the detection threshold)")
    d_det = pairwise_distances(det)
    d_lay = pairwise_distances(lay)
    best = None
    candidates: dict[frozenset, tuple] = {}  # assignment -> (score, r, t): one entry per distinct solution
    iu = np.triu_indices(len(det), 1)
    perfect = min(len(lay), len(det))
    extra_seeds = 0
    for a, b, c in _seed_triangles(lay, max_seeds, tuple(layout.groups)):
        ok_ab = np.abs(d_det[iu] - d_lay[a, b]) <= tolerance_m
        for i0, j0 in zip(iu[0][ok_ab], iu[1][ok_ab]):
            for i, j in ((i0, j0), (j0, i0)):
                ks = np.nonzero((np.abs(d_det[i] - d_lay[a, c]) <= tolerance_m)
                                & (np.abs(d_det[j] - d_lay[b, c]) <= tolerance_m))[0]
                for k in ks:
                    if k in (i, j):
                        continue
                    seed = fit_rigid(lay[[a, b, c]], det[[i, j, k]])
                    r, t = seed.rotation, seed.translation
                    pairs = _assign(seed.apply(lay), det, tolerance_m)
                    levelled = max_tilt_deg is None or tilt_deg(r, up_layout) <= max_tilt_deg
                    score = (levelled, len(pairs), -sum(p[2] for p in pairs))
                    key = frozenset((p[0], p[1]) for p in pairs)
                    if key not in candidates or score > candidates[key][0]:
                        candidates[key] = (score, r, t)
                    if best is None or score > best[0]:
                        best = (score, r, t)
        if best is not None and best[0][0] and best[0][1] >= perfect:
            # every detection matched by a levelled solution: a few more seeds, to see a rival if there is one
            extra_seeds += 1
            if extra_seeds > TIE_SEEDS:
                break
    if best is None or best[0][1] < 3:
        raise ProcessingError("the detections do not match the layout: no three detected reflectors have the "
                              "layout's distances (check the layout coordinates, the target diameter and the coarse scan)")
    rival = _rival(best, candidates)
    if rival is not None:
        raise ProcessingError(
            f"two identifications fit the {best[0][1]} detected reflectors equally well (the layout is symmetric "
            f"for what was detected: {rival}); refusing to guess. Scan so that a deck target is detected, add "
            "an asymmetric target, or remove the wrong window by hand")
    _, r, t = best
    fit = Transform.from_rt(r, t)
    for _ in range(4):  # refine on all matches
        pairs = _assign(fit.apply(lay), det, tolerance_m)
        fit = fit_rigid(lay[[p[0] for p in pairs]], det[[p[1] for p in pairs]])
    r, t = fit.rotation, fit.translation
    pred = fit.apply(lay)
    pairs = _assign(pred, det, tolerance_m)
    by_layout = {p[0]: p for p in pairs}
    matches = []
    for i_lay, rid in enumerate(layout.ids):
        if i_lay in by_layout:
            _, di, res = by_layout[i_lay]
            matches.append(TargetMatch(rid, layout.groups[i_lay], tuple(float(v) for v in det[di]), di, res))
        else:
            matches.append(TargetMatch(rid, layout.groups[i_lay], tuple(float(v) for v in pred[i_lay]), None, None))
    used = {p[1] for p in pairs}
    rms = float(np.sqrt(np.mean([p[2] ** 2 for p in pairs])))
    return Identification(tuple(matches), r, t, rms, tuple(i for i in range(len(det)) if i not in used),
                          tilt_deg(r, up_layout))

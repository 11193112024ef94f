"""Identification of detected reflectors against the campaign layout.

Only rigid-invariant geometry is used: congruent triangles of pairwise
distances propose a correspondence, a rigid fit (Kabsch) scores it by the
number of layout reflectors it explains, and the best one is refined on all
matches. The layout may be in any frame (design drawings, a total station).
Unmatched detections and layout reflectors without a detection are reported;
the latter get a position predicted from the fit, marked as predicted.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import combinations

import numpy as np
from numpy.typing import ArrayLike
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from common.arrays import unique_sorted
from common.errors import InputError, ProcessingError
from common.rigid import Transform, fit_rigid, pairwise_distances
from lidar.layout import Layout, target_normals
from lidar.scanner_profile import MAX_TILT_DEG


@dataclass(frozen=True)
class TargetMatch:
    """One layout reflector in this scan.

    ``detection`` is the index of the matched detection, or None when the
    position is ``predicted`` from the layout fit (not resolved or not seen).
    """

    id: str
    group: str
    xyz_socs: tuple[float, ...]
    detection: int | None
    residual_m: float | None

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


def _seed_triangles(xyz: np.ndarray, limit: int, groups: tuple | None = None) -> list[tuple[int, int, int]]:
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
    """Unique layout->detection pairs closer than ``tol`` (optimal assignment), in layout order.

    As many pairs as possible, and of those the smallest sum of distances. Each group of layout targets and
    detections that compete for each other (usually one target and one detection) is solved on its own;
    scipy's assignment solver is imported only for a group too large to enumerate (its import costs 0.3 s).
    """
    d = np.linalg.norm(pred[:, None, :] - det[None, :, :], axis=2)
    near = d <= tol
    pairs: list[tuple[int, int]] = []
    for rows, cols in _competing_groups(near):
        if len(rows) == 1 or len(cols) == 1:
            sub = d[np.ix_(rows, cols)]
            k = int(np.argmin(sub))
            pairs.append((rows[k // len(cols)], cols[k % len(cols)]))
            continue
        best = _enumerate_matchings(rows, near, d)
        if best is None:
            return _assign_scipy(d, tol)
        pairs.extend(best)
    return [(r, c, float(d[r, c])) for r, c in sorted(pairs)]


def _competing_groups(near: np.ndarray) -> list[tuple[list[int], list[int]]]:
    """Connected groups (layout rows, detection columns) of the bipartite graph ``near``, by first row."""
    n_rows = near.shape[0]
    r, c = np.nonzero(near)
    # the bipartite graph's groups: rows are nodes 0.., columns after them; groups are numbered in the order of
    # their first node, so in the order of their first row
    n_nodes = n_rows + near.shape[1]
    _, group = connected_components(coo_matrix((np.ones(r.size), (r, n_rows + c)), shape=(n_nodes, n_nodes)),
                                    directed=False)
    out = []
    for g in unique_sorted(group[r]):
        rows = np.flatnonzero(group[:n_rows] == g)
        out.append(([int(k) for k in rows], [int(k) for k in np.flatnonzero(group[n_rows:] == g)]))
    return out


def _enumerate_matchings(rows: list[int], near: np.ndarray, d: np.ndarray,
                         limit: int = 4096) -> list[tuple[int, int]] | None:
    """The matching of one group with the most pairs, then the smallest distance sum; None if too large."""
    options = [[int(c) for c in np.flatnonzero(near[r])] for r in rows]
    if np.prod([len(o) + 1 for o in options], dtype=float) > limit:
        return None
    best: tuple[int, float, list[tuple[int, int]]] = (-1, 0.0, [])

    def walk(k: int, used: frozenset, chosen: list[tuple[int, int]], total: float) -> None:
        nonlocal best
        if k == len(rows):
            if len(chosen) > best[0] or (len(chosen) == best[0] and total < best[1]):
                best = (len(chosen), total, list(chosen))
            return
        for c in options[k]:
            if c not in used:
                walk(k + 1, used | {c}, chosen + [(rows[k], c)], total + float(d[rows[k], c]))
        walk(k + 1, used, chosen, total)

    walk(0, frozenset(), [], 0.0)
    return best[2]


def _assign_scipy(d: np.ndarray, tol: float) -> list[tuple[int, int, float]]:
    # local: scipy.optimize costs plan-file 0.09-0.1 s of start-up (measured); few layouts need it
    from scipy.optimize import linear_sum_assignment

    rows, cols = linear_sum_assignment(np.where(d <= tol, d, 1e6))
    return [(int(r), int(c), float(d[r, c])) for r, c in zip(rows, cols, strict=False) if d[r, c] <= tol]


#: Seeds tried after a perfect levelled solution, to find an equally good rival.
TIE_SEEDS = 6


def _rivals(best, candidates: dict) -> list:
    """Other levelled solutions as good as the best one (different assignments), best first.

    As good: as many matches, and residuals no larger than the layout's own errors could make them
    (1.5 times the best's, or 2 cm a match more).
    """
    (lev, count, neg_sum), _, _ = best
    out = []
    for key, (score, r, t) in candidates.items():
        lev2, count2, neg_sum2 = score
        if score == best[0] or lev2 != lev or count2 != count:
            continue
        if -neg_sum2 <= max(-neg_sum * 1.5, -neg_sum + 0.02 * count) + 0.01 * count:
            out.append((key, score, r, t))
    return sorted(out, key=lambda x: x[1], reverse=True)


#: A solution is preferred to its rival when it leaves this many fewer visible targets unseen.
EVIDENCE_MARGIN = 2
#: A target is expected in the coarse scan when it faces the scanner at least this well (|cos| of incidence),
#: and lies within this many times the farthest detection's range.
EVIDENCE_MIN_COS = 0.35
EVIDENCE_REACH = 2.5


def _unseen(r: np.ndarray, t: np.ndarray, layout: Layout, matched: set, det: np.ndarray,
            evidence: Callable[[np.ndarray], object], up_layout: ArrayLike) -> int:
    """How many targets a solution puts where the coarse scan says they are not, less those it explains.

    ``evidence(xyz)`` says, for a target the solution did not match to a detection: False where a target
    facing the scanner within reach should have shown and the map shows nothing bright; ``"through"``
    where the scan looked straight through the position (a target hanging in the air), whatever its
    facing; True where the map does show a target there (one the blob search missed). The first two
    count against the solution, the third for it.
    """
    normals = target_normals(layout, up=up_layout) @ np.asarray(r).T
    pred = layout.xyz @ np.asarray(r).T + t
    reach = EVIDENCE_REACH * float(np.max(np.linalg.norm(det, axis=1)))
    count = 0
    for i in range(len(layout.ids)):
        if i in matched:
            continue
        rng = float(np.linalg.norm(pred[i]))
        if not rng > 0.5:
            continue
        verdict = evidence(pred[i])
        facing = rng <= reach and float(normals[i] @ (-pred[i] / rng)) >= EVIDENCE_MIN_COS
        if verdict == "through" or (verdict is False and facing):
            count += 1
        elif verdict is True:
            count -= 1
    return count


#: Detection triangles (the largest) tried as seeds against every congruent layout triangle.
DETECTION_SEEDS = 10


def _best_triangle(best, lay: np.ndarray, det: np.ndarray, tol: float) -> tuple[int, int, int] | None:
    """The largest triangle of the detections a solution matched (None with fewer than three)."""
    _, r, t = best
    dets = [p[1] for p in _assign(lay @ np.asarray(r).T + t, det, tol)]
    if len(dets) < 3:
        return None
    return max(combinations(dets, 3), key=lambda c: _triangle_area(det[list(c)]))


def _congruent_solutions(tri: tuple[int, int, int] | None, candidates: dict, lay: np.ndarray, det: np.ndarray,
                         d_lay: np.ndarray, d_det: np.ndarray, tol: float, max_tilt_deg: float | None,
                         up_layout: ArrayLike) -> None:
    """Add to ``candidates`` every solution mapping the detection triangle ``tri`` onto a congruent layout triangle.

    A layout that repeats itself (identical spans, identical piers) has several places the detected part
    of it fits; seeds drawn from the whole layout may find one of them only. Every layout triangle
    congruent with a triangle of detections (the best solution's largest, and the largest of all the
    detections) gives a solution here, so that :func:`_settle_rivals` sees them all.
    """
    if tri is None:
        return
    i, j, k = tri
    n = len(lay)
    wide = 2.0 * tol  # the layout's errors add up over a triangle's sides: search wide, judge by the assignment
    ab = np.argwhere(np.abs(d_lay - d_det[i, j]) <= wide)
    for a, b in ab:
        if a == b:
            continue
        cs = np.nonzero((np.abs(d_lay[a] - d_det[i, k]) <= wide) & (np.abs(d_lay[b] - d_det[j, k]) <= wide))[0]
        for c in cs:
            if c in (a, b) or c >= n:
                continue
            seed = fit_rigid(lay[[a, b, c]], det[[i, j, k]])
            cand = _assign(seed.apply(lay), det, tol)
            for _ in range(2):  # refine on everything it matched, as the identification's own refinement does
                if len(cand) < 3:
                    break
                seed = fit_rigid(lay[[q[0] for q in cand]], det[[q[1] for q in cand]])
                cand = _assign(seed.apply(lay), det, tol)
            levelled = max_tilt_deg is None or tilt_deg(seed.rotation, up_layout) <= max_tilt_deg
            score = (levelled, len(cand), -sum(p[2] for p in cand))
            key = frozenset((p[0], p[1]) for p in cand)
            if key not in candidates or score > candidates[key][0]:
                candidates[key] = (score, seed.rotation, seed.translation)


def _triangle_area(xyz: np.ndarray) -> float:
    """The area of a triangle of three points: the largest fixes a rigid fit best."""
    return float(0.5 * np.linalg.norm(np.cross(xyz[1] - xyz[0], xyz[2] - xyz[0])))


#: A station hint settles two identifications when their stations lie this much farther apart from it (metres).
STATION_MARGIN_M = 10.0


def _by_station(options: list, station_xy: ArrayLike | None) -> tuple | None:
    """The option whose scanner position (in the layout's frame) is clearly the nearest to ``station_xy``."""
    if station_xy is None:
        return None
    hint = np.asarray(station_xy, dtype=np.float64)[:2]
    # layout -> scanner is x_s = R x_l + t: the scanner's origin sits at -R^T t in the layout's frame
    dist = [float(np.linalg.norm((-np.asarray(r).T @ np.asarray(t))[:2] - hint)) for _, _, r, t in options]
    order = np.argsort(dist, kind="stable")
    if dist[order[1]] - dist[order[0]] >= STATION_MARGIN_M:
        _, score, r, t = options[order[0]]
        return (score, r, t)
    return None


def _settle_rivals(best, candidates: dict, layout: Layout, det: np.ndarray,
                   evidence: Callable[[np.ndarray], object] | None, up_layout: ArrayLike,
                   station_xy: ArrayLike | None = None):
    """The best solution, or a rival the coarse scan's evidence (then the station hint) prefers.

    Refused when nothing tells them apart.
    """
    rivals = _rivals(best, candidates)
    if not rivals:
        return best
    best_key = next(k for k, v in candidates.items() if v[0] == best[0])
    if evidence is not None:
        options = [(best_key, *best)] + rivals
        unseen = [_unseen(r, t, layout, {i for i, _ in key}, det, evidence, up_layout)
                  for key, _, r, t in options]
        order = np.argsort(unseen, kind="stable")
        if unseen[order[1]] - unseen[order[0]] >= EVIDENCE_MARGIN:
            _, score, r, t = options[order[0]]
            return (score, r, t)
    settled = _by_station([(best_key, *best)] + rivals, station_xy)
    if settled is not None:
        return settled
    swapped = sorted(set(rivals[0][0]) - set(best_key))
    raise ProcessingError(
        f"two identifications fit the {best[0][1]} detected reflectors equally well (the layout is symmetric "
        f"for what was detected: {len(swapped)} reflector(s) would be assigned differently); refusing to guess. "
        "Say roughly where the scanner stood ('bridgesurvey settings DIR station_xy X,Y', layout metres, within "
        f"{STATION_MARGIN_M / 2:g} m), scan so that more of the bridge is seen, or add an asymmetric target")


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
                        max_seeds: int = 60, max_tilt_deg: float | None = MAX_TILT_DEG,
                        up_layout: ArrayLike = (0.0, 0.0, 1.0),
                        evidence: Callable[[np.ndarray], object] | None = None,
                        station_xy: ArrayLike | None = None) -> Identification:
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
    evidence : callable, optional, keyword-only
        ``evidence(xyz_socs) -> True | False | "through" | None``: whether the coarse scan shows a target at a
        position, shows none, looked straight through it (nothing there but farther surfaces), or cannot tell. When two solutions fit the detections equally well - a layout that repeats
        itself, like the identical spans of a multi-span bridge, seen in part - the one that leaves
        :data:`EVIDENCE_MARGIN` fewer targets unseen where it puts them facing the scanner wins.
    station_xy : (2,) sequence, optional, keyword-only
        Roughly where the scanner stands, in the layout's frame (metres). When the evidence cannot settle two
        solutions (a symmetric bridge turned end for end fits the same detections), the one that puts the
        scanner :data:`STATION_MARGIN_M` nearer to it wins.

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
        for i0, j0 in zip(iu[0][ok_ab], iu[1][ok_ab], strict=False):
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
    # seeds from the detections' own largest triangles too: when few targets were detected, the layout's
    # best triangles rarely consist of detected ones only
    for tri in sorted(combinations(range(len(det)), 3), key=lambda c: -_triangle_area(det[list(c)]))[:DETECTION_SEEDS]:
        _congruent_solutions(tri, candidates, lay, det, d_lay, d_det, tolerance_m, max_tilt_deg, up_layout)
    if candidates:
        best = max(candidates.values(), key=lambda v: v[0])
    if best is None or best[0][1] < 3:
        raise ProcessingError("the detections do not match the layout: no three detected reflectors have the "
                              "layout's distances (check the layout coordinates, the target diameter and the coarse scan)")
    _congruent_solutions(_best_triangle(best, lay, det, tolerance_m), candidates, lay, det, d_lay, d_det, tolerance_m,
                         max_tilt_deg, up_layout)
    best = max(candidates.values(), key=lambda v: v[0])
    best = _settle_rivals(best, candidates, layout, det, evidence, up_layout, station_xy)
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

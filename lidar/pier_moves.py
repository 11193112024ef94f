"""Pinning an ambiguous pier-target move with the deck's shape.

When one of two pier targets moved, the reference check can find two
explanations that fit the pier targets equally well: "A moved" and "B moved"
(a vertical move of the upper of two stacked targets looks like a pitch of the
whole frame about the other pier). Each explanation gives the deck its own
displacements, and they differ by that pitch: a linear ramp along the span.

A deck supported on its piers cannot have such a ramp: its displacement
vanishes at both supports. So each explanation's deck displacements are
fitted, per girder line, by the two lowest bending shapes of a span supported
at both ends (``sin(pi xi)`` and ``sin(2 pi xi)``, ``xi`` from 0 at one pier to
1 at the other), weighted by their sigmas. The explanation whose deck fits
(chi-square below its 99 % quantile) while the other's does not by a wide
margin is taken: its target is named as moved, and the other one is kept.
Otherwise both stay left out and are named as suspects.

The same test checks a single target the reference check named as moved,
when the deck's shape under that choice is implausible.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np

from common.errors import SurveyError
from common.flags import FLAG_REFERENCE_AMBIGUOUS, FLAG_REFERENCE_MOVED, FLAG_REFERENCE_UNRESOLVED
from lidar.displacement_result import EpochDisplacements

#: How much worse (chi-square ratio) the rejected explanation must fit than the kept one.
DECISIVE_RATIO = 4.0
#: An explanation's pier targets must fit one rigid motion within this factor of the best explanation's.
CONSISTENCY_RATIO = 3.0
#: Deck targets whose across-span positions differ by less than this are on one girder line (m).
LINE_TOLERANCE_M = 0.5


def _chi2_99(dof: float) -> float:
    """The chi-square distribution's 99 % quantile (scipy.stats imported here: it costs every command 1 s)."""
    # local: scipy.stats costs status and every campaign command 0.4 s of start-up (measured)
    from scipy.stats import chi2

    return float(chi2.ppf(0.99, dof))

def span_coordinates(base: Mapping, groups: Mapping[str, str], meas: list[str]
                     ) -> tuple[np.ndarray, np.ndarray] | None:
    """Xi in [0, 1] of each deck target between the piers, and its girder line, from the baseline geometry.

    Returns ``(xi, lines)``, each (len(meas),): the position along the span between the outermost reference
    targets and the girder line's index (0, 1, …, across the deck); None when those references span under 1 m.
    """
    refs = [r for r, g in groups.items() if g == "reference" and r in base]
    deck = np.array([base[m].xyz for m in meas])
    c = deck - deck.mean(axis=0)
    _, vecs = np.linalg.eigh(c.T @ c)
    along, across = vecs[:, -1], vecs[:, -2]
    piers = np.array([base[r].xyz for r in refs]) @ along
    lo, hi = float(piers.min()), float(piers.max())
    if hi - lo < 1.0:
        return None
    xi = (deck @ along - lo) / (hi - lo)
    side = deck @ across
    lines = np.zeros(len(meas), int)
    order = np.argsort(side)
    for a, b in zip(order[:-1], order[1:], strict=False):
        lines[b] = lines[a] + (side[b] - side[a] > LINE_TOLERANCE_M)
    return xi, lines


def deck_shape_chi2(result: EpochDisplacements, base: Mapping, groups: Mapping[str, str]) -> tuple[float, int] | None:
    """(chi-square, degrees of freedom) of the deck displacements against the supported-span shapes.

    None when there are too few deck targets for any degree of freedom.
    """
    ds = [d for d in result.displacements if np.isfinite(d.displacement_m) and d.sigma_m > 0 and d.reflector in base]
    if len(ds) < 3:
        return None
    geo = span_coordinates(base, groups, [d.reflector for d in ds])
    if geo is None:
        return None
    xi, lines = geo
    n_lines = int(lines.max()) + 1
    cols = []
    for line in range(n_lines):
        on = lines == line
        for k in (1, 2):
            cols.append(np.where(on, np.sin(k * np.pi * xi), 0.0))
    a = np.column_stack(cols)
    keep = np.abs(a).sum(axis=0) > 0
    a = a[:, keep]
    u = np.array([d.displacement_m for d in ds])
    s = np.array([d.sigma_m for d in ds])
    dof = len(ds) - np.linalg.matrix_rank(a)
    if dof < 1:
        return None
    coef, *_ = np.linalg.lstsq(a / s[:, None], u / s, rcond=None)
    r = (u - a @ coef) / s
    return float(r @ r), int(dof)


def resolve_ambiguous_move(result: EpochDisplacements, base: Mapping, groups: Mapping[str, str], solve: Callable,
                           consistency: Callable[[list], float]) -> EpochDisplacements:
    """Try every pier target as the one that moved; keep the explanation the deck's shape supports.

    Called when the reference check could not tell which of two targets moved
    (it names them as suspects and leaves both out). Each pier target in turn
    is taken as the moved one (the suspects are often right, but a third
    target's move can make two innocent ones look alike); an explanation
    counts when its remaining pier targets are as consistent as the check's
    (``consistency(stable_ids)``, a rigid-fit RMS) and its deck fits a supported
    span. One that fits while every other fits decisively worse is taken: its
    target is named as moved and the others are kept. ``solve(stable_ids,
    checks, flags)`` recomputes the epoch. Otherwise ``result`` stands (both suspects left out), with
    ``reference_move_unresolved`` (a problem) on the epoch and on every row: two pier targets on one pier
    leave the deck's tilt to the deck itself, and its errors reach 5-15 sigma.
    """
    suspects = [c.reflector for c in result.reference_checks if c.suspect]
    if len(suspects) != 2:
        return result
    present = list(result.reference_ids) + suspects
    rms = {m: consistency([r for r in present if r != m]) for m in present if len(present) - 1 >= 3}
    if not rms:  # too few pier targets to try the explanations
        return _unresolved(result)
    limit = CONSISTENCY_RATIO * min(rms.values()) + 1e-4
    fits = []
    for moved in present:
        stable = [r for r in present if r != moved]
        if moved not in rms or rms[moved] > limit:
            continue
        checks = tuple(replace(c, suspect=False, moved=(c.moved and c.reflector not in present) or c.reflector == moved)
                       for c in result.reference_checks)
        flags = [f for f in result.flags if f != FLAG_REFERENCE_AMBIGUOUS]
        if FLAG_REFERENCE_MOVED not in flags:
            flags.append(FLAG_REFERENCE_MOVED)
        fit = _explain(solve, stable, checks, flags, base, groups)
        if fit is not None:
            fits.append(fit)
    return _decisive(fits) or _unresolved(result)


def _explain(solve: Callable, stable: list, checks, flags: list, base: Mapping, groups: Mapping[str, str]):
    """(chi-square, dof, result) of one explanation, or None when it cannot be computed or judged."""
    try:
        candidate = solve(stable, checks, flags)
    except SurveyError:  # an explanation that cannot be computed is no explanation
        return None
    shape = deck_shape_chi2(candidate, base, groups)
    return None if shape is None else (shape[0], shape[1], candidate)


def _decisive(fits: list):
    """The one explanation whose deck fits (99 %) while all others fit at least DECISIVE_RATIO times worse."""
    if not fits:
        return None
    fits = sorted(fits, key=lambda f: f[0])
    c1, dof1, best = fits[0]
    if c1 > _chi2_99(dof1):
        return None
    if len(fits) > 1 and fits[1][0] < DECISIVE_RATIO * max(c1, dof1):
        return None
    return best


def verify_single_move(result: EpochDisplacements, base: Mapping, groups: Mapping[str, str], solve: Callable,
                       consistency: Callable[[list], float]) -> EpochDisplacements:
    """Check the one pier target the reference check named as moved against the deck's shape.

    When the deck displacements under that explanation do not fit a supported
    span (chi-square above its 99 % quantile), each other pier target is tried
    as the moved one instead (same conditions as :func:`resolve_ambiguous_move`).
    When none is decisively better, the best-fitting explanation is kept and the
    epoch and every row carry ``reference_move_unresolved`` (a problem): the check's
    own choice is the one the deck rejects, so it cannot stand unflagged.
    """
    moved = [c.reflector for c in result.reference_checks if c.moved]
    if len(moved) != 1 or len(result.reference_ids) < 3:
        return result
    named = moved[0]
    shape = deck_shape_chi2(result, base, groups)
    if shape is None or shape[0] <= _chi2_99(shape[1]):
        return result
    present = list(result.reference_ids) + [named]
    limit = 2.0 * consistency(list(result.reference_ids)) + 2e-4
    fits = [(shape[0], shape[1], result)]
    for other in result.reference_ids:
        stable = [r for r in present if r != other]
        if consistency(stable) > limit:
            continue
        checks = tuple(replace(c, moved=c.reflector == other if c.reflector in (other, named) else c.moved)
                       for c in result.reference_checks)
        fit = _explain(solve, stable, checks, list(result.flags), base, groups)
        if fit is not None:
            fits.append(fit)
    return _decisive(fits) or _unresolved(min(fits, key=lambda f: f[0])[2])


def _unresolved(result: EpochDisplacements) -> EpochDisplacements:
    """``result`` with ``reference_move_unresolved`` on the epoch and on every row."""
    rows = tuple(replace(d, flags=d.flags + (FLAG_REFERENCE_UNRESOLVED,)) for d in result.displacements)
    return replace(result, displacements=rows, flags=result.flags + (FLAG_REFERENCE_UNRESOLVED,))

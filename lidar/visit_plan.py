"""A visit's set-ups planned together: each target from the set-up that measures it best, one time budget.

Planned alone, each set-up of a visit spends its budget on every target it sees: on targets another set-up
measures better, while the targets both see only weakly get no time from either (issue 40). Planned
together (:func:`plan_visit`):

* every target's height sigma is predicted from every set-up's coarse scan (range, incidence and share of
  the beam: :func:`predicted_sigma_mm`); a deck target is planned in the set-up with the smallest one (a set-up whose
  coarse scan did not find it counts :data:`PREDICTED_PENALTY` times its sigma);
* a reference (pier) target is planned in every set-up that sees it well (not weak): it fixes each set-up's
  own scale and drift, and it joins the set-ups;
* each further set-up keeps *tie targets*: shared with the set-ups before it, seen well (not weak) from both,
  at least :data:`TIES` of them and chosen to spread as far off a line as the candidates allow, because the
  join (:func:`lidar.setups.join_setups`) needs three well-spread ones and leaves a misfit out;
* the time the visit's budget leaves then goes to second sightings of deck targets from another set-up that sees
  them well (largest gain in their height sigma first; the join combines the two);
* the visit's budget is shared among the set-ups in proportion to the time each one's windows need, and each
  set-up is planned in its share (:func:`lidar.plan.plan_fine_scans`, its closure window included);
* a target no set-up can resolve is left to the set-up that comes closest, whose plan says why it is not
  planned.

The set-ups are worked in their order (set-up 1 is the frame the others are joined into).

A set-up whose fine scans are already imported is *frozen* (:attr:`SetupTargets.frozen`: the plan its scans were
made with). On site the second station's coarse scan usually comes after the first station's fine scans: planning
together then plans only the set-ups still to come and takes the frozen plans as given. A target a frozen set-up
planned and sees well is not assigned again; one it planned weakly goes to a set-up to come that measures it better;
the ties of a set-up to come are drawn from what the frozen set-ups' windows hold; the budget the set-ups to come
share is what the frozen ones left of the visit's (a frozen set-up planned as if it were alone is charged at most
the budget its plan had). The frozen set-ups come first in the order of work.

The visit's budget is the caller's: the campaign gives a visit planned together ``budget_min`` a set-up unless
``visit_budget_min`` says otherwise (:func:`projects.processing.parameters.visit_budget_seconds`), the same total
time its set-ups would have planned alone. The VZ-1000 spends about two minutes a window turning the head and
starting, so a window costs nearly the same at 100 points as at 1000: a visit short of time cannot buy much by
spreading fewer points, and its plans say so in one line (:func:`_short_line`) before the visit.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from common.errors import InputError
from lidar.centroid import UNRESOLVED_RATIO, WEAK_RATIO, resolvability
from lidar.plan import DEFAULT_INCIDENCE_COS, PlanTarget, ScanPlan, plan_fine_scans, plan_roi
from lidar.prediction import centroid_covariance
from lidar.scanner_profile import VZ1000, ScannerProfile
from lidar.setups import MIN_SHARED, MIN_SPREAD_M, spread_m

#: Tie targets a further set-up keeps with the set-ups before it: one more than the join needs, so that a shared
#: target left out as a misfit (:data:`lidar.setups.OUTLIER_SIGMA`) does not leave the set-up unjoined.
TIES = MIN_SHARED + 1
#: The spread (m, RMS off their line) the ties are chosen to reach: twice what the join refuses below.
TIE_SPREAD_M = 2.0 * MIN_SPREAD_M
#: A target the coarse scan did not find (its position predicted from the layout) goes to that set-up only when it
#: measures it this much better than one that found it: its window is 2.5 times as wide (it costs several times the
#: time) and may miss the target.
PREDICTED_PENALTY = 1.25
#: The fewest points per target the shares of a visit's budget are made for (the planner's own floor is 50).
MIN_SHARED_POINTS = 100


@dataclass(frozen=True)
class SetupTargets:
    """One set-up of a visit as its coarse scan saw it: the targets it could plan, in its own scanner frame."""

    setup: int
    targets: tuple[PlanTarget, ...]
    profile: ScannerProfile = VZ1000
    #: The plan its fine scans were made with, when they are imported: it is taken as given, not planned again.
    frozen: ScanPlan | None = None
    #: A frozen plan made as if the set-up were the visit's only one: it had a budget of its own (its plan's
    #: ``budget_seconds``), and is charged at most that of the visit's budget the set-ups to come share.
    frozen_alone: bool = False


@dataclass(frozen=True)
class VisitPlan:
    """The fine-scan plans of a visit's set-ups, made together.

    Attributes
    ----------
    epoch : str
    plans : mapping set-up -> ScanPlan
        Each set-up's plan (the plan JSON contract), planned in its share of the budget.
    assignment : mapping id -> set-up
        The set-up measuring each target best (smallest predicted height sigma).
    ties : mapping set-up -> tuple of str
        The targets each further set-up shares with the set-ups before it (what joins it).
    predicted_sigma_mm : mapping set-up -> mapping id -> float
        Predicted height sigma of each target's centroid from each set-up, mm (inf: not resolved from there).
    budget_seconds : float
        The visit's budget, shared among the set-ups (each plan's ``budget_seconds`` is its share).
    order : tuple of int
        The order in which to work the set-ups.
    warnings : tuple of str
        What the surveyor must act on for the visit as a whole (a set-up that cannot be joined, a visit too short
        for the points asked).
    elsewhere : mapping set-up -> mapping id -> set-up
        The targets a set-up sees but leaves to another set-up.
    second : mapping set-up -> tuple of str
        Deck targets a set-up scans as a second sighting, in the time the budget leaves.
    """

    epoch: str
    plans: Mapping[int, ScanPlan]
    assignment: Mapping[str, int]
    ties: Mapping[int, tuple[str, ...]]
    predicted_sigma_mm: Mapping[int, Mapping[str, float]]
    budget_seconds: float
    order: tuple[int, ...]
    warnings: tuple[str, ...] = ()
    elsewhere: Mapping[int, Mapping[str, int]] = field(default_factory=dict)
    second: Mapping[int, tuple[str, ...]] = field(default_factory=dict)

    @property
    def total_seconds(self) -> float:
        """The fine scans of every set-up, seconds."""
        return float(sum(p.total_seconds for p in self.plans.values()))

    def plan(self, setup: int) -> ScanPlan:
        """Set-up ``setup``'s plan."""
        if setup not in self.plans:
            raise InputError(f"the visit has no set-up {setup} (set-ups {', '.join(map(str, self.order))})")
        return self.plans[setup]

    def summary(self, setup: int) -> dict:
        """What set-up ``setup``'s plan JSON says of the visit (the ``visit`` entry beside the contract's keys)."""
        plan = self.plan(setup)
        return {"setup": setup, "setups": list(self.order), "position_in_order": self.order.index(setup) + 1,
                "visit_budget_seconds": round(self.budget_seconds, 2),
                "visit_total_seconds": round(self.total_seconds, 2),
                "budget_share_seconds": round(plan.budget_seconds, 2),
                "ties": list(self.ties.get(setup, ())), "second_sightings": list(self.second.get(setup, ())),
                "measured_elsewhere": {k: v for k, v in sorted(self.elsewhere.get(setup, {}).items())},
                "warnings": list(self.warnings)}

    def to_json(self) -> dict:
        """The whole visit: every set-up's plan (the plan JSON contract each) in the order of work."""
        return {"epoch": self.epoch, "budget_seconds": round(self.budget_seconds, 2),
                "total_seconds": round(self.total_seconds, 2), "order": list(self.order),
                "assignment": dict(sorted(self.assignment.items())), "warnings": list(self.warnings),
                "setups": [dict(self.plans[k].to_json(), setup=k, visit=self.summary(k)) for k in self.order]}


def predicted_sigma_mm(target: PlanTarget, *, profile: ScannerProfile = VZ1000, min_points: int = 1000) -> float:
    """Predicted sigma of a target's centroid height from one station, mm (inf when the beam cannot resolve it).

    The points come from the window the planner would make (:func:`lidar.plan.plan_roi`: the instrument's finest
    steps limit them at long range); the covariance from :func:`lidar.prediction.centroid_covariance`, with the
    grazing term processing adds to a disc narrower than the beam. The target's normal is its layout normal
    carried into the scanner frame (``normal_socs``); without one it is taken in the vertical plane of the line
    of sight at the target's incidence, as a deck target's is.

    Examples
    --------
    >>> near = PlanTarget("M1", "measurement", (0.0, 15.0, 6.0), 0.05, incidence_cos=0.37)
    >>> far = PlanTarget("M1", "measurement", (0.0, 60.0, 6.0), 0.05, incidence_cos=0.1)
    >>> predicted_sigma_mm(near) < predicted_sigma_mm(far)
    True
    """
    xyz = np.asarray(target.xyz_socs, dtype=np.float64)
    r = float(np.linalg.norm(xyz))
    cos = float(target.incidence_cos if target.incidence_cos is not None else DEFAULT_INCIDENCE_COS)
    if not (math.isfinite(r) and r > 0.1) or resolvability(target.diameter_m, cos, r, profile) < UNRESOLVED_RATIO:
        return math.inf
    n = max(plan_roi(target, n_points=min_points, profile=profile).expected_target_points, 1)
    normal = _normal(target, xyz, cos)
    cov = centroid_covariance(xyz, normal, n, diameter_m=target.diameter_m, range_noise_m=profile.range_noise_m,
                              profile=profile)
    return float(math.sqrt(max(cov[2, 2], 0.0)) * 1e3)


def _normal(target: PlanTarget, xyz: np.ndarray, cos: float) -> np.ndarray:
    """The target's normal in the scanner frame (its own, or one at its incidence facing the scanner)."""
    if target.normal_socs is not None:
        return np.asarray(target.normal_socs, dtype=np.float64)
    view = xyz / np.linalg.norm(xyz)
    up = np.array([0.0, 0.0, 1.0])
    across = up - (up @ view) * view
    n = float(np.linalg.norm(across))
    across = across / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])
    side = -1.0 if xyz[2] > 0 else 1.0  # a target above the scanner faces down toward it
    c = min(max(cos, 0.0), 1.0)
    return -c * view + side * math.sqrt(1.0 - c * c) * across


def _weak(t: PlanTarget, profile: ScannerProfile) -> bool:
    cos = float(t.incidence_cos if t.incidence_cos is not None else DEFAULT_INCIDENCE_COS)
    return resolvability(t.diameter_m, cos, float(np.linalg.norm(t.xyz_socs)), profile) < WEAK_RATIO


def plan_visit(setups: Sequence[SetupTargets], *, epoch: str = "", min_points: int = 1000,
               budget_seconds: float = 3600.0, margin_m: float = 0.10, closure: bool = False,
               reference_factor: float = 1.0) -> VisitPlan:
    """Plan the fine scans of a visit's set-ups together (see the module's description).

    Parameters
    ----------
    setups : sequence of SetupTargets
        Every set-up of the visit with the targets its coarse scan identified (detected or predicted), each in
        its own scanner frame; set-up numbers distinct.
    epoch : str, keyword-only
    min_points : int, keyword-only
        Points each target should receive. Default 1000.
    budget_seconds : float, keyword-only
        Time for the fine scans of the whole visit, seconds. Default 3600.
    margin_m : float, keyword-only
        Background around each target inside its window, metres. Default 0.10.
    closure : bool, keyword-only
        End each set-up's plan with its closure window (:func:`lidar.plan.plan_fine_scans`). Default False.
    reference_factor : float, keyword-only
        More points on the reference targets, from the time every target's points leave
        (:func:`lidar.plan.plan_fine_scans`). Default 1.

    Returns
    -------
    VisitPlan
        With one set-up, its plan is :func:`lidar.plan.plan_fine_scans`'s, unchanged.
    """
    if not setups:
        raise InputError("nothing to plan: the visit has no set-up")
    numbers = [s.setup for s in setups]
    if len(set(numbers)) != len(numbers):
        raise InputError("a visit's set-ups must have distinct numbers")
    if not budget_seconds > 0:
        raise InputError("the time budget must be positive")
    by_setup = {s.setup: s for s in setups}
    frozen = tuple(sorted(k for k in numbers if by_setup[k].frozen is not None))
    order = frozen + tuple(sorted(k for k in numbers if k not in frozen))  # the frozen ones were worked first
    kw: dict[str, Any] = {"epoch": epoch, "min_points": min_points, "margin_m": margin_m, "closure": closure,
                          "reference_factor": reference_factor}
    sigma = {k: {t.id: predicted_sigma_mm(t, profile=by_setup[k].profile, min_points=min_points)
                 for t in by_setup[k].targets} for k in order}
    if len(order) == 1 and not frozen:
        (k,) = order
        plan = plan_fine_scans(by_setup[k].targets, profile=by_setup[k].profile, budget_seconds=budget_seconds, **kw)
        return VisitPlan(epoch, {k: plan}, {t.id: k for t in by_setup[k].targets}, {}, sigma, float(budget_seconds),
                         order)
    chosen, assignment, elsewhere = _assign(by_setup, order, sigma)
    ties, warnings = _ties(by_setup, order, sigma, chosen)
    given: dict[int, ScanPlan] = {k: p for k in frozen if (p := by_setup[k].frozen) is not None}
    spent = float(sum(min(p.total_seconds, p.budget_seconds) if by_setup[k].frozen_alone else p.total_seconds
                      for k, p in given.items()))
    seconds = _second_sightings(by_setup, order, sigma, chosen, budget_seconds - spent, kw)
    elsewhere = {k: {t: j for t, j in elsewhere[k].items() if t not in chosen[k]} for k in order}
    plans = dict(given)
    shared, short = _share_budget(by_setup, tuple(k for k in order if k not in frozen), chosen,
                                  budget_seconds - spent, kw, spent=spent)
    plans.update(shared)
    warnings += [short] if short else []
    return VisitPlan(epoch, plans, assignment, ties, sigma, float(budget_seconds), order, tuple(warnings), elsewhere,
                     seconds)


def _held(s: SetupTargets) -> set[str]:
    """The targets a frozen set-up's plan has windows for (its closure window aside)."""
    return {r.reflector for r in s.frozen.rois if not r.closure} if s.frozen is not None else set()


def _assign(by_setup: Mapping[int, SetupTargets], order: tuple[int, ...], sigma: Mapping[int, Mapping[str, float]]
            ) -> tuple[dict[int, set[str]], dict[str, int], dict[int, dict[str, int]]]:
    """Which targets each set-up plans (before the ties), each target's best set-up, and who measures what instead.

    A frozen set-up's targets are its plan's; a target it sees well there stays its, one it holds weakly goes to a
    set-up to come that measures it better.
    """
    ids = sorted({t.id for k in order for t in by_setup[k].targets})
    chosen: dict[int, set[str]] = {k: _held(by_setup[k]) for k in order}
    free = [k for k in order if by_setup[k].frozen is None]
    assignment: dict[str, int] = {}

    def score(k: int, tid: str) -> tuple[float, int]:
        return (sigma[k].get(tid, math.inf) * (PREDICTED_PENALTY if _target(by_setup[k], tid).predicted else 1.0),
                order.index(k))

    for tid in ids:
        held = [k for k in order if by_setup[k].frozen is not None and tid in chosen[k] and tid in sigma[k]]
        well = [k for k in held if math.isfinite(sigma[k][tid]) and not _weak(_target(by_setup[k], tid),
                                                                                by_setup[k].profile)]
        if well:  # measured well already: not assigned again
            assignment[tid] = min(well, key=lambda k: score(k, tid))
            continue
        seen = [k for k in free if tid in sigma[k]] + held
        if not seen:  # only frozen set-ups see it, and none planned it: the first one's plan says why
            assignment[tid] = next(k for k in order if tid in sigma[k])
            continue
        best = min(seen, key=lambda k: score(k, tid))
        if not math.isfinite(sigma[best][tid]):  # nobody resolves it: the closest says why in its plan
            best = max(seen, key=lambda k: (_share(by_setup[k], tid), -order.index(k)))
        assignment[tid] = best
        chosen[best].add(tid)
    for k in free:  # a reference target fixes every set-up that sees it well: its scale, drift and join
        for t in by_setup[k].targets:
            if t.group == "reference" and math.isfinite(sigma[k][t.id]) and not _weak(t, by_setup[k].profile):
                chosen[k].add(t.id)
    elsewhere = {k: {t.id: assignment[t.id] for t in by_setup[k].targets if t.id not in chosen[k]} for k in order}
    return chosen, assignment, elsewhere


def _target(s: SetupTargets, tid: str) -> PlanTarget:
    return next(t for t in s.targets if t.id == tid)


def _share(s: SetupTargets, tid: str) -> float:
    t = _target(s, tid)
    cos = float(t.incidence_cos if t.incidence_cos is not None else DEFAULT_INCIDENCE_COS)
    return resolvability(t.diameter_m, cos, float(np.linalg.norm(t.xyz_socs)), s.profile)


def _ties(by_setup: Mapping[int, SetupTargets], order: tuple[int, ...], sigma: Mapping[int, Mapping[str, float]],
          chosen: dict[int, set[str]]) -> tuple[dict[int, tuple[str, ...]], list[str]]:
    """Add each further set-up's tie targets to ``chosen`` (both sides); returns the ties and what cannot be joined.

    Candidates are seen well (resolved, not weak) from the set-up and from one before it (from a frozen one: in a
    window of its plan). They are added one at a time, those both coarse scans found before those predicted from the
    layout (a predicted window may miss its target), each the one that spreads the shared targets furthest off
    their line (in the set-up's frame), until :data:`TIES` are shared and they spread :data:`TIE_SPREAD_M`, and
    :data:`TIES` of them were found by both coarse scans when the candidates allow. A frozen
    set-up gets no ties: its windows are scanned.
    """
    ties: dict[int, tuple[str, ...]] = {}
    warnings: list[str] = []
    for pos, k in enumerate(order[1:], start=1):
        if by_setup[k].frozen is not None:
            continue
        before = order[:pos]
        mine = {t.id: t for t in by_setup[k].targets}
        good = {tid for tid, t in mine.items()
                if math.isfinite(sigma[k][tid]) and not _weak(t, by_setup[k].profile)}
        sharp_before = {j: {t.id for t in by_setup[j].targets
                            if math.isfinite(sigma[j][t.id]) and not _weak(t, by_setup[j].profile)
                            and (by_setup[j].frozen is None or t.id in chosen[j])} for j in before}
        shared = sorted(tid for tid in chosen[k] & good if any(tid in chosen[j] and tid in sharp_before[j]
                                                               for j in before))
        pool = sorted(tid for tid in good - set(shared) if any(tid in sharp_before[j] for j in before))
        spread = _spread_of(mine)
        # found by the coarse scans of the set-up and of one before it that sees it well
        found = {tid for tid in good if not mine[tid].predicted and any(
            tid in sharp_before[j] and not _target(by_setup[j], tid).predicted for j in before)}
        while pool and (len(shared) < TIES or spread(shared) < TIE_SPREAD_M
                        or (len(found.intersection(shared)) < TIES and not found.isdisjoint(pool))):
            best = max(pool, key=lambda tid: (tid in found, round(spread([*shared, tid]), 3),
                                              -max(sigma[k][tid], min(sigma[j][tid] for j in before
                                                                      if tid in sharp_before[j])), tid))
            pool.remove(best)
            shared.append(best)
            chosen[k].add(best)
            if not any(best in chosen[j] for j in before if best in sharp_before[j]):
                other = min((j for j in before if best in sharp_before[j]), key=lambda j: (sigma[j][best], j))
                chosen[other].add(best)
        ties[k] = tuple(sorted(shared))
        if len(shared) < MIN_SHARED or spread(shared) < MIN_SPREAD_M:
            warnings.append(f"set-up {k} sees only {len(shared)} target(s) well that the set-ups before it also see "
                            f"({', '.join(sorted(shared)) or 'none'}, spread {spread(shared):.2f} m): it cannot be "
                            f"joined ({MIN_SHARED} targets spread {MIN_SPREAD_M:g} m off a line are needed); "
                            "move it where it sees more of their targets, or add a set-up between them "
                            "(stations --first proposes three set-ups when no pair joins)")
    return ties, warnings


def _second_sightings(by_setup: Mapping[int, SetupTargets], order: tuple[int, ...],
                      sigma: Mapping[int, Mapping[str, float]], chosen: dict[int, set[str]], budget_seconds: float,
                      kw: dict) -> dict[int, tuple[str, ...]]:
    """Spend the time the visit's budget leaves on second sightings of deck targets (added to ``chosen``; returned).

    A target seen well (not weak) from another set-up too is scanned from there as well when time is left: the
    join combines the two sightings by their covariances. Only set-ups still to come (not frozen) add any;
    ``budget_seconds`` is what the frozen ones left. The largest gains in the target's height sigma come first;
    a weak sighting is never added (the join leaves it out beside a sharp one).
    """
    free = [k for k in order if by_setup[k].frozen is None]
    need = sum(plan_fine_scans([t for t in by_setup[k].targets if t.id in chosen[k]], profile=by_setup[k].profile,
                               budget_seconds=1e9, **dict(kw, reference_factor=1.0)).total_seconds
               for k in free if chosen[k])  # the reference targets' extra points come after the second sightings
    spare = budget_seconds - need
    added: dict[int, list[str]] = {k: [] for k in order}
    if spare <= 0:
        return {}
    best: dict[str, float] = {}
    for k in order:
        for tid in chosen[k]:
            best[tid] = min(best.get(tid, math.inf), sigma[k][tid])
    offers = []
    for k in free:
        for t in by_setup[k].targets:
            s_k, s_0 = sigma[k][t.id], best.get(t.id, math.inf)
            if t.id in chosen[k] or t.group != "measurement" or not math.isfinite(s_k) or not math.isfinite(s_0) \
                    or _weak(t, by_setup[k].profile):
                continue
            gain = s_0 - 1.0 / math.sqrt(1.0 / s_0 ** 2 + 1.0 / s_k ** 2)
            seconds = plan_roi(t, n_points=kw["min_points"], profile=by_setup[k].profile,
                               margin_m=kw["margin_m"]).expected_seconds
            offers.append((-gain, k, t.id, seconds))
    for _, k, tid, seconds in sorted(offers):
        if seconds <= spare:
            chosen[k].add(tid)
            added[k].append(tid)
            spare -= seconds
    return {k: tuple(sorted(v)) for k, v in added.items() if v}


def _spread_of(targets: Mapping[str, PlanTarget]):
    """``spread(ids)``: how far the targets ``ids`` spread off their line, metres (:func:`lidar.setups.spread_m`)."""
    def spread(ids) -> float:
        return spread_m(np.array([targets[i].xyz_socs for i in ids], dtype=np.float64).reshape(-1, 3))
    return spread


def _share_budget(by_setup: Mapping[int, SetupTargets], order: tuple[int, ...], chosen: Mapping[int, set[str]],
                  budget_seconds: float, kw: dict, *, spent: float = 0.0) -> tuple[dict[int, ScanPlan], str]:
    """Each set-up of ``order`` planned in its share of ``budget_seconds``.

    ``budget_seconds`` is what the visit's budget leaves after the ``spent`` seconds of the frozen set-ups.

    The shares give every set-up's targets the same points: the most points per target (up to ``min_points``) whose
    windows all fit the visit's budget, found by bisection; each share is its set-up's time at those points, and
    time left over is shared in proportion. When even :data:`MIN_SHARED_POINTS` do not fit, each set-up gets its time
    at those points and every plan says the visit is over its budget. When the budget gives targets fewer points
    than ``min_points``, the visit says so in one line (:func:`_short_line`, returned beside the plans; empty when
    it gives every target its points): which targets, and the visit's time that would give them their points.
    """
    if not order:
        return {}, ""
    budget_seconds = max(budget_seconds, 0.0)
    targets = {k: [t for t in by_setup[k].targets if t.id in chosen[k]] for k in order}
    for k in order:
        if not targets[k]:
            raise InputError(f"set-up {k} has nothing to measure that another set-up does not measure better, "
                             "and nothing to join it: leave it out of the visit")

    def times(points: float) -> dict[int, float]:  # the reference targets' extra points come from what is left
        args = dict(kw, min_points=max(int(points), 10), reference_factor=1.0)
        return {k: max(plan_fine_scans(targets[k], profile=by_setup[k].profile, budget_seconds=1e9,
                                       **args).total_seconds, 1e-6) for k in order}

    full = times(kw["min_points"])
    need = dict(full)
    if sum(need.values()) > budget_seconds:
        lo, hi = float(MIN_SHARED_POINTS), float(kw["min_points"])
        if sum(times(lo).values()) <= budget_seconds:
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if sum(times(mid).values()) <= budget_seconds else (lo, mid)
        need = times(lo)
    total = sum(need.values())
    spare = max(budget_seconds - total, 0.0)
    share = {k: need[k] + spare * need[k] / total for k in order}
    plans = {k: plan_fine_scans(targets[k], profile=by_setup[k].profile, budget_seconds=share[k], **kw)
             for k in order}
    return plans, _short_line(by_setup, order, targets, plans, full, budget_seconds, spent, kw)


def _short_line(by_setup: Mapping[int, SetupTargets], order: tuple[int, ...], targets: Mapping[int, list],
                plans: Mapping[int, ScanPlan], full: Mapping[int, float], budget_seconds: float, spent: float,
                kw: dict) -> str:
    """One line, before the visit, when its budget gives targets fewer points than asked: which, and the time needed.

    A target is short when its window in the plan gets fewer points than the same window planned without a time
    limit (points the instrument's finest steps cannot give are no shortage of time). ``full``: each set-up's time
    with every target at ``min_points``. Empty when the budget gives every target its points.
    """
    short: list[tuple[str, int]] = []
    for k in order:
        roomy = {r.reflector: r.expected_target_points  # (the reference targets' extra points are no shortage)
                 for r in plan_fine_scans(targets[k], profile=by_setup[k].profile, budget_seconds=1e9,
                                          **dict(kw, reference_factor=1.0)).rois
                 if not r.closure}
        planned = {r.reflector: r.expected_target_points for r in plans[k].rois if not r.closure}
        short.extend((tid, planned.get(tid, 0)) for tid, n in roomy.items() if planned.get(tid, 0) < 0.95 * n)
    if not short:
        return ""
    need = sum(full.values()) + spent
    ids = sorted({tid for tid, _ in short}, key=lambda t: (len(t), t))
    every = {t.id for k in order for t in targets[k]}
    named = f"every target ({len(ids)})" if set(ids) == every else ", ".join(ids)
    windows = sum(len(p.rois) for p in plans.values())
    overhead = sum(by_setup[k].profile.window_overhead_s * len(plans[k].rois) for k in order)
    have = budget_seconds + spent
    scanned = f" ({spent / 60:.0f} of them already scanned)" if spent > 0 else ""
    return (f"the visit's {have / 60:.0f} min{scanned} are too short for {kw['min_points']} points a target: "
            f"{named} would get fewer (down to {min(n for _, n in short)}; its {windows} windows spend "
            f"{overhead / 60:.0f} min turning and starting whatever their points); about {math.ceil(need / 60)} min "
            f"({math.ceil((need - have) / 60)} more) would give every target its points: set visit_budget_min to "
            f"{math.ceil(need / 60)}, or leave a set-up out")

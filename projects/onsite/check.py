"""The on-site check, right after the fine scans are imported: is every target good enough to leave.

For each planned target: found or not, points on the target against the plan, and the vertical
centroid sigma against the goal (the sigma the plan's points promise, with 30 % tolerance, or the
campaign's ``sigma_goal_mm``). Targets that fall short get a re-scan plan in the plan JSON contract,
with steps scaled by what the scan actually delivered.

A visit of several set-ups gets one verdict once every set-up has its fine scans (:func:`check_visit`): a target
one set-up missed or measured short is no re-scan when another set-up measured it well, unless the join needs it
(a set-up must keep :data:`lidar.setups.MIN_SHARED` targets measured in common with the set-ups before it).
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from common.errors import ProcessingError
from common.flags import FLAG_MOVED_DURING_SCAN, FLAG_TRANSIENT_REMOVED, code
from common.progress import ProgressCallback, scaled
from lidar.angles import direction_from_angles
from lidar.plan import PlanTarget, ScanPlan, plan_fine_scans
from lidar.prediction import centroid_covariance
from lidar.setups import MIN_SHARED
from lidar.systematic.corrections import closure_drift
from projects.processing.stages import run_stage1, save_stage1, stage1_job
from projects.store.campaign import Campaign

POINTS_TOLERANCE = 0.7  # fewer than 70 % of the planned points: re-scan
SIGMA_TOLERANCE = 1.3  # sigma over 130 % of the promised one: re-scan
STATUSES = ("ok", "short", "imprecise", "moved", "not found")


@dataclass(frozen=True)
class TargetCheck:
    """One target of the check.

    Attributes
    ----------
    points, planned_points : int
        Disc points measured, and promised by the plan.
    sigma_mm, goal_sigma_mm : float
        Vertical standard deviation of the centroid, and the goal, mm (NaN when not found).
    status : {"ok", "short", "imprecise", "moved", "not found"}
    """

    reflector: str
    group: str
    found: bool
    points: int
    planned_points: int
    sigma_mm: float
    goal_sigma_mm: float
    status: str
    note: str = ""

    def to_json(self) -> dict:
        def num(v):
            return None if not math.isfinite(v) else round(float(v), 4)
        return {"reflector": self.reflector, "group": self.group, "found": self.found, "points": self.points,
                "planned_points": self.planned_points,
                "points_ratio": None if not self.planned_points else round(self.points / self.planned_points, 3),
                "sigma_mm": num(self.sigma_mm), "goal_sigma_mm": num(self.goal_sigma_mm), "status": self.status,
                "note": self.note}


@dataclass(frozen=True)
class ClosureCheck:
    """The plan's closure window: how far the set-up turned during the visit, against what the instrument allows.

    ``status`` is ``ok``, ``drifted`` (beyond the instrument's tolerance by more than 3 sigma: re-scan
    advised) or ``not measured`` (the scans carry no point times, so the closure cannot be told from the
    first window).
    """

    reflector: str
    status: str
    angle_arcsec: float = float("nan")
    sigma_arcsec: float = float("nan")
    minutes: float = float("nan")
    tolerance_arcsec: float = float("nan")
    note: str = ""

    def to_json(self) -> dict:
        def num(v: float) -> float | None:
            return None if not math.isfinite(v) else round(v, 2)

        return {"reflector": self.reflector, "status": self.status, "drift_arcsec": num(self.angle_arcsec),
                "drift_sigma_arcsec": num(self.sigma_arcsec), "minutes": num(self.minutes),
                "tolerance_arcsec": num(self.tolerance_arcsec), "note": self.note}


def _closure_check(plan: ScanPlan, cents: dict, closures: dict) -> ClosureCheck | None:
    """The closure verdict of a measured epoch (None when its plan has no closure window)."""
    roi = next((r for r in plan.rois if r.closure), None)
    if roi is None:
        return None
    tol = float(plan.profile.drift_tolerance_arcsec)
    first, last = cents.get(roi.reflector), closures.get(roi.reflector)
    if first is None or last is None or not first.found or not last.found:
        why = "the fine scans carry no point times" if last is None else "the target was not found in both windows"
        return ClosureCheck(roi.reflector, "not measured", tolerance_arcsec=tol,
                            note=f"{why}: the set-up's drift cannot be read off the closure")
    d = closure_drift(first, last)
    drifted = d.angle_arcsec - 3 * d.sigma_arcsec > tol
    note = (f"the set-up turned {d.angle_arcsec:.1f}\" +- {d.sigma_arcsec:.1f}\" in {d.dt_s / 60:.0f} min, beyond "
            f"the {tol:g}\" the instrument allows: re-scan advised") if drifted else ""
    return ClosureCheck(roi.reflector, "drifted" if drifted else "ok", d.angle_arcsec, d.sigma_arcsec, d.dt_s / 60.0,
                        tol, note)


@dataclass(frozen=True)
class EpochCheck:
    """The on-site check of an epoch's fine scans: each target's verdict and the re-scan plan (or None)."""

    epoch: str
    targets: tuple[TargetCheck, ...]
    rescan: ScanPlan | None
    closure: ClosureCheck | None = None

    @property
    def short(self) -> tuple[TargetCheck, ...]:
        return tuple(t for t in self.targets if t.status != "ok")

    def to_json(self) -> dict:
        return {"epoch": self.epoch, "ok": not self.short, "targets": [t.to_json() for t in self.targets],
                "rescan": None if self.rescan is None else self.rescan.to_json(),
                "closure": None if self.closure is None else self.closure.to_json()}


def check_epoch(c: Campaign, label: str, *, goal_sigma_mm: float | None = None, setup: int = 1,
                progress: ProgressCallback | None = None) -> EpochCheck:
    """Measure the epoch's (set-up's) fine scans and judge every planned target (see the module notes).

    The verdict is kept in the campaign (:meth:`Campaign.check_verdict`): a re-scan it asks for is the visit's next
    step, and processing the epoch without it needs the user's word (:func:`pending_rescans`).
    """
    job = stage1_job(c, label, setup)  # one read of the store; an unknown epoch says so
    if not job.fine_paths:
        where = f"set-up {setup} of epoch {label}" if setup != 1 else f"epoch {label}"
        raise ProcessingError(f"{where} has no fine scans yet; import them with 'bridgesurvey add-fine' first")
    if goal_sigma_mm is not None and not (math.isfinite(goal_sigma_mm) and goal_sigma_mm > 0):
        raise ProcessingError(f"the sigma goal must be a positive number of millimetres, got {goal_sigma_mm}")
    result = run_stage1(job, progress=progress)  # the plan it measured with, and the centroids
    save_stage1(c, result)
    cents, plan = result.centroids or {}, result.plan
    closures = result.closures or {}
    layout = job.layout
    diam = {i: float(d) for i, d in zip(layout.ids, layout.diameters_m, strict=False)}
    rows, retry = [], []
    for roi in plan.rois:
        if roi.closure:
            continue
        cent = cents.get(roi.reflector)
        # without point times the closure window's points add to the first window's
        planned = int(roi.expected_target_points) + sum(int(r.expected_target_points) for r in plan.rois
                                                        if r.closure and r.reflector == roi.reflector
                                                        and r.reflector not in closures)
        d = diam.get(roi.reflector, 0.05)
        if cent is None or not cent.found:
            rows.append(TargetCheck(roi.reflector, roi.group, False, 0 if cent is None else int(cent.n_points), planned,
                                    float("nan"), float("nan"), "not found",
                                    "no disc in the window: check the line of sight and that the target is there"))
            retry.append((roi, None, 1.0))
            continue
        sigma = 1000.0 * math.sqrt(max(float(cent.cov[2, 2]), 0.0))
        if goal_sigma_mm is None:
            noise = cent.sigma_range_m if math.isfinite(cent.sigma_range_m) and cent.sigma_range_m > 0 \
                else plan.profile.range_noise_m
            normal = cent.normal_socs if np.all(np.isfinite(cent.normal_socs)) else -cent.xyz_socs
            promised = centroid_covariance(cent.xyz_socs, normal, max(planned, 1), diameter_m=d, range_noise_m=noise,
                                           profile=plan.profile)
            goal = SIGMA_TOLERANCE * 1000.0 * math.sqrt(promised[2, 2])
        else:
            goal = float(goal_sigma_mm)
        ratio = cent.n_points / planned if planned else 1.0
        moved = [f for f in cent.flags if code(f) in (FLAG_MOVED_DURING_SCAN, FLAG_TRANSIENT_REMOVED)]
        if moved and code(moved[0]) == FLAG_MOVED_DURING_SCAN:
            status, note = "moved", moved[0].split(": ", 1)[1] + ": scan it again when nothing crosses"
        elif ratio < POINTS_TOLERANCE:
            status, note = "short", f"{cent.n_points} of {planned} planned points"
        elif sigma > goal:
            status, note = "imprecise", f"sigma {sigma:.3f} mm over the goal {goal:.3f} mm"
        else:
            status, note = "ok", ""
        if moved and status != "moved":
            note = "; ".join(x for x in (note, moved[0].split(": ", 1)[1] + " (sigma widened)") if x)
        if any(n.startswith("weak:") for n in roi.notes):
            note = "; ".join(x for x in (note, "weak from here (grazing, sigma widened): measure it from another "
                                               "set-up if one sees it better") if x)
        rows.append(TargetCheck(roi.reflector, roi.group, True, int(cent.n_points), planned, sigma, goal, status, note))
        if status != "ok":
            retry.append((roi, cent, ratio))
    out = EpochCheck(label, tuple(rows), _rescan_plan(plan, retry, diam) if retry else None,
                     _closure_check(plan, cents, closures))
    # the verdict binds what comes next (the re-scan, and 'process' asks first): kept in the campaign
    c.save_check_verdict(label, setup=setup, rescan={t.reflector: t.status if not t.found else t.note or t.status
                                                          for t in out.short},
                         drifted=out.closure is not None and out.closure.status == "drifted")
    return out


def pending_rescans(c: Campaign, epochs) -> dict:
    """``epoch -> CheckVerdict`` of the ``epochs`` whose check asked for a re-scan neither made nor accepted."""
    out = {}
    for label in epochs:
        verdict = c.check_verdict(label)
        if verdict is not None and verdict.asks_rescan:
            out[label] = verdict
    return out


def _rescan_plan(plan: ScanPlan, retry, diam: dict) -> ScanPlan:
    """Windows for the targets that fell short, aimed at the measured centroid.

    The incidence is scaled by what the scan delivered (the planner then picks finer steps).
    """
    targets = []
    for roi, cent, ratio in retry:
        cos_planned = math.cos(math.radians(roi.incidence_deg)) if math.isfinite(roi.incidence_deg) else None
        if cent is not None:
            xyz = tuple(float(v) for v in cent.xyz_socs)
            cos_eff = None if cos_planned is None else float(np.clip(cos_planned * max(ratio, 0.05), 0.05, 1.0))
            targets.append(PlanTarget(roi.reflector, roi.group, xyz, diam.get(roi.reflector, 0.05), False, cos_eff))
        else:
            tc, pc = roi.window.centre
            xyz = tuple(float(v) for v in direction_from_angles(tc, pc) * roi.range_m)
            targets.append(PlanTarget(roi.reflector, roi.group, xyz, diam.get(roi.reflector, 0.05), True, cos_planned))
    out = plan_fine_scans(targets, epoch=plan.epoch, profile=plan.profile, min_points=plan.min_points,
                          budget_seconds=plan.budget_seconds)
    return out


@dataclass(frozen=True)
class VisitCheck:
    """One verdict for a visit of several set-ups.

    Attributes
    ----------
    epoch : str
    setups : mapping set-up -> EpochCheck
        Each set-up's own check (its re-scan plan cut to what the visit needs).
    rescan : mapping set-up -> mapping id -> str
        What each set-up must re-scan, and why (empty: the visit is complete).
    covered : mapping id -> int
        Targets a set-up fell short on that another set-up measured well (that set-up): no re-scan.
    """

    epoch: str
    setups: Mapping[int, EpochCheck]
    rescan: Mapping[int, Mapping[str, str]]
    covered: Mapping[str, int]

    @property
    def drifted(self) -> tuple[int, ...]:
        """The set-ups whose closure says they turned beyond the instrument's tolerance."""
        return tuple(k for k, ch in self.setups.items() if ch.closure is not None and ch.closure.status == "drifted")

    @property
    def ok(self) -> bool:
        return not any(self.rescan.values()) and not self.drifted

    def to_json(self) -> dict:
        return {"epoch": self.epoch, "ok": self.ok, "setups": sorted(self.setups),
                "rescan": {str(k): dict(v) for k, v in sorted(self.rescan.items()) if v},
                "covered": {t: k for t, k in sorted(self.covered.items())}, "drifted": list(self.drifted)}


def visit_verdict(label: str, checks: Mapping[int, EpochCheck]) -> VisitCheck:
    """The visit's verdict from each set-up's check (pure; see the module notes)."""
    order = sorted(checks)
    planned = {k: {t.reflector for t in checks[k].targets} for k in order}
    found = {k: {t.reflector for t in checks[k].targets if t.found} for k in order}
    good = {k: {t.reflector for t in checks[k].targets if t.status == "ok"} for k in order}
    rescan: dict[int, dict[str, str]] = {k: {} for k in order}
    for pos, k in enumerate(order[1:], start=1):  # the join: each set-up keeps MIN_SHARED found in common
        earlier = order[:pos]
        shared_found = found[k] & set().union(*(found[j] for j in earlier))
        if len(shared_found) >= MIN_SHARED:
            continue
        why = (f"the join needs it: set-up {k} has {len(shared_found)} target(s) measured in common with the set-ups "
               f"before it, {MIN_SHARED} are needed")
        for t in sorted(planned[k] & set().union(*(planned[j] for j in earlier)) - shared_found):
            where = k if t not in found[k] else next(j for j in earlier if t in planned[j] and t not in found[j])
            rescan[where][t] = why
    covered: dict[str, int] = {}
    for k in order:
        for row in checks[k].short:
            if row.reflector in rescan[k]:
                continue
            other = next((j for j in order if j != k and row.reflector in good[j]), None)
            if other is not None:
                covered[row.reflector] = other
            else:
                rescan[k][row.reflector] = row.status if not row.found else row.note or row.status
    cut = {}
    for k in order:
        ch = checks[k]
        keep = set(rescan[k])
        plan = None if ch.rescan is None or not keep else replace(
            ch.rescan, rois=tuple(r for r in ch.rescan.rois if r.reflector in keep))
        cut[k] = replace(ch, rescan=plan)
    return VisitCheck(label, cut, rescan, covered)


def check_visit(c: Campaign, label: str, *, goal_sigma_mm: float | None = None,
                progress: ProgressCallback | None = None) -> VisitCheck:
    """Check every set-up of a visit and give one verdict (each set-up's kept verdict holds only what the visit needs).

    Every set-up with a coarse scan must have its fine scans (the check of the whole visit comes after the last).
    """
    setups = [k for k in c.setups(label) if c.files(label, "coarse", setup=k)]
    waiting = [k for k in setups if not c.files(label, "fine", setup=k)]
    if waiting:
        raise ProcessingError(f"set-up(s) {', '.join(map(str, waiting))} of epoch {label} have no fine scans yet: the "
                              "visit's verdict comes after the last set-up ('check --setup K' checks one)")
    checks = {}
    for n, k in enumerate(setups):
        checks[k] = check_epoch(c, label, goal_sigma_mm=goal_sigma_mm, setup=k,
                                progress=scaled(progress, n / len(setups), (n + 1) / len(setups)))
    out = visit_verdict(label, checks)
    for k, ch in out.setups.items():  # what binds the visit's next step: only the re-scans it needs
        c.save_check_verdict(label, setup=k, rescan=dict(out.rescan[k]),
                             drifted=ch.closure is not None and ch.closure.status == "drifted")
    return out

"""The reflector pipeline end to end for one epoch: coarse scan -> plan -> fine scans -> centroids.

Each step is also available on its own in its module; these functions only chain them.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from common.flags import FLAG_NOT_FOUND, FLAG_UNRESOLVED
from common.progress import ProgressCallback, report, scaled
from lidar.centroid import TargetCentroid, measure_windows
from lidar.detection import DetectionResult, detect_reflectors
from lidar.guided_detection import (
    bright_near,
    map_top,
    missing_note,
    missing_reasons,
    recover_predicted,
    seen_through,
)
from lidar.identification import Identification, identify_reflectors
from lidar.layout import Layout, target_normals
from lidar.plan import PlanTarget, ScanPlan, coarse_step_needed_deg, incidence_from_map, plan_fine_scans
from lidar.reflectance_map import ReflectanceMap, reflectance_map
from lidar.scan import Scan
from lidar.scanner_profile import MAX_TILT_DEG, VZ1000, ScannerProfile


@dataclass(frozen=True, eq=False)
class CoarseAnalysis:
    """What the coarse scan of an epoch tells: map, detections, identification, incidence per target.

    ``missing_why`` says, for each target the scan did not find (its position predicted from the layout), why
    (:func:`lidar.guided_detection.missing_reasons`); ``missing_note`` says it in one line.
    """

    reflectance_map: ReflectanceMap
    detections: DetectionResult
    identification: Identification
    incidence_cos: Mapping[str, float | None]
    missing_why: Mapping[str, str] = field(default_factory=dict)

    @property
    def missing_note(self) -> str | None:
        """One line naming the targets not found in the coarse scan and why (None when all were found)."""
        return missing_note(dict(self.missing_why), len(self.identification.matches))


def _need_intensity(scan: Scan, what: str) -> np.ndarray:
    """The scan's intensities; a scan without them is refused with what needs them."""
    if scan.intensity is None:
        raise InputError(f"{scan.source or scan.name}: the scan has no intensity values; {what} needs them "
                         "(export the scan with intensity/reflectance)")
    return scan.intensity


def _map_evidence(rmap: ReflectanceMap, threshold: float, tolerance_m: float):
    """``evidence(xyz)`` for :func:`lidar.identification.identify_reflectors`, from the coarse map."""
    top: list[float] = []  # the map's top, found once when first needed

    def evidence(xyz: np.ndarray) -> object:
        if seen_through(rmap, xyz):
            return "through"
        if not top:
            top.append(map_top(rmap))
        return bright_near(rmap, xyz, threshold, tolerance_m=tolerance_m, top=top[0])
    return evidence


def analyse_coarse(scan: Scan, layout: Layout, *, step_deg: float | None = None, threshold: float | None = None,
                   tolerance_m: float = 0.15, max_tilt_deg: float | None = MAX_TILT_DEG,
                   up_layout: ArrayLike = (0.0, 0.0, 1.0), station_xy: ArrayLike | None = None,
                   progress: ProgressCallback | None = None) -> CoarseAnalysis:
    """Reflectance map, detection and identification of a coarse scan.

    ``max_tilt_deg``, ``up_layout`` and ``station_xy`` go to :func:`lidar.identification.identify_reflectors`
    (None for a scanner that was not levelled).
    """
    intensity = _need_intensity(scan, "reflector detection")
    rmap = reflectance_map(scan.xyz_socs, intensity, step_deg=step_deg, progress=scaled(progress, 0, 0.8))
    return analyse_map(rmap, layout, threshold=threshold, tolerance_m=tolerance_m, max_tilt_deg=max_tilt_deg,
                       up_layout=up_layout, station_xy=station_xy, progress=scaled(progress, 0.8, 1.0))


def analyse_map(rmap: ReflectanceMap, layout: Layout, *, threshold: float | None = None,
                tolerance_m: float = 0.15, max_tilt_deg: float | None = MAX_TILT_DEG,
                up_layout: ArrayLike = (0.0, 0.0, 1.0), station_xy: ArrayLike | None = None,
                progress: ProgressCallback | None = None) -> CoarseAnalysis:
    """Detection and identification on a coarse scan's reflectance map (see :func:`analyse_coarse`)."""
    diameter = float(np.median(layout.diameters_m))
    det = detect_reflectors(rmap, target_diameter_m=diameter, threshold=threshold)
    report(progress, 0.5, "identifying reflectors")
    ident = identify_reflectors(det.xyz(), layout, tolerance_m=tolerance_m, max_tilt_deg=max_tilt_deg,
                                up_layout=up_layout, evidence=_map_evidence(rmap, det.threshold, tolerance_m),
                                station_xy=station_xy)
    det, ident = recover_predicted(rmap, det, ident, tolerance_m=tolerance_m)
    inc = {m.id: incidence_from_map(rmap, m.xyz_socs) for m in ident.matches}
    why = missing_reasons(rmap, det, ident, tolerance_m=tolerance_m)
    report(progress, 1.0, "coarse scan analysed")
    return CoarseAnalysis(rmap, det, ident, inc, why)


def layout_normals_socs(identification: Identification, layout: Layout, *,
                        up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> dict[str, np.ndarray]:
    """Every identified target's normal (the layout's ``nx,ny,nz`` or its default) in the scanner frame."""
    normals = target_normals(layout, up=up_layout)
    return {m.id: identification.rotation @ normals[layout.index(m.id)] for m in identification.matches}


def layout_incidence(identification: Identification, layout: Layout, *,
                     up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> dict[str, float]:
    """|cos| of the incidence angle at every identified target, from the layout's normals.

    The normals (``nx,ny,nz`` or the defaults of :func:`lidar.layout.target_normals`) are carried
    into the scanner frame by the rotation fitted to the detected targets (:func:`layout_normals_socs`); the
    viewing direction is the target's position (detected, or predicted from the layout). A target facing away
    from the scanner gets 0.
    """
    normals = layout_normals_socs(identification, layout, up_layout=up_layout)
    out = {}
    for m in identification.matches:
        xyz = np.asarray(m.xyz_socs, dtype=np.float64)
        view = -xyz / np.linalg.norm(xyz)
        out[m.id] = max(0.0, float(normals[m.id] @ view))
    return out


def plan_targets(coarse: CoarseAnalysis, layout: Layout, *,
                 up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> list[PlanTarget]:
    """What the planner needs of every layout reflector the coarse scan identified (detected or predicted).

    Incidence comes from the layout's target normals carried into the scanner frame
    (:func:`layout_incidence`), for detected and predicted targets alike: the surface around a
    target in a coarse map is often another face (a pier corner, the deck edge).
    """
    normals = layout_normals_socs(coarse.identification, layout, up_layout=up_layout)
    inc = layout_incidence(coarse.identification, layout, up_layout=up_layout)
    return [PlanTarget(m.id, m.group, tuple(float(v) for v in m.xyz_socs),
                       float(layout.diameters_m[layout.index(m.id)]), m.predicted, max(inc[m.id], 0.05),
                       tuple(float(v) for v in normals[m.id])) for m in coarse.identification.matches]


def coarse_notes(coarse: CoarseAnalysis, targets: Sequence[PlanTarget], plan: ScanPlan) -> tuple[str, ...]:
    """What a plan's warnings add from its coarse scan: the targets it did not find and why, the step they need."""
    return tuple(n for n in (coarse.missing_note, _coarse_step_note(targets, plan, coarse.reflectance_map.step_deg))
                 if n)


def plan_from_coarse(coarse: CoarseAnalysis, layout: Layout, *, epoch: str = "", profile: ScannerProfile = VZ1000,
                     min_points: int = 1000, budget_seconds: float = 3600.0, margin_m: float = 0.10,
                     up_layout: ArrayLike = (0.0, 0.0, 1.0), closure: bool = False,
                     reference_factor: float = 1.0) -> ScanPlan:
    """Fine-scan plan for every layout reflector (detected or predicted; :func:`plan_targets`).

    ``closure`` ends the plan with the first reference target's window again, and ``reference_factor`` gives the
    reference targets that many times the points where the time allows (see :func:`lidar.plan.plan_fine_scans`).
    The plan's warnings say which targets the coarse scan did not find and why (:attr:`CoarseAnalysis.missing_note`).
    """
    targets = plan_targets(coarse, layout, up_layout=up_layout)
    plan = plan_fine_scans(targets, epoch=epoch, profile=profile, min_points=min_points,
                           budget_seconds=budget_seconds, margin_m=margin_m, closure=closure,
                           reference_factor=reference_factor)
    notes = coarse_notes(coarse, targets, plan)
    return replace(plan, warnings=plan.warnings + notes) if notes else plan


def _coarse_step_note(targets, plan: ScanPlan, step_deg: float) -> str | None:
    """What the coarse scan's step could not resolve: the planned targets it did not find and the step they need."""
    planned = {r.reflector for r in plan.rois}
    short = {t.id: coarse_step_needed_deg(t.diameter_m, t.incidence_cos or 1.0, float(np.linalg.norm(t.xyz_socs)))
             for t in targets if t.predicted and t.id in planned}
    short = {k: v for k, v in short.items() if v < step_deg}
    if not short:
        return None
    need = min(short.values())
    return (f"the coarse scan's cell ({step_deg:.3f} deg) is wider than {', '.join(sorted(short))} need(s) to be "
            f"found (their windows come from the layout alone): scan the coarse at {need:.3f} deg or finer from "
            "this station to find them")


@dataclass(frozen=True, eq=False)
class FineMeasurement:
    """The centroids of an epoch's fine scans, its closure centroids, and where their times come from.

    ``time_source`` is ``points`` (the scans carry point times), ``plan`` (they do not: each centroid's
    time is its window's in the plan's order and time model, and the closure cannot be told from its
    first pass) or ``none`` (the plan has no time model either).
    """

    centroids: Mapping[str, TargetCentroid]
    closures: Mapping[str, TargetCentroid]
    time_source: str


def plan_times(plan: ScanPlan) -> dict[str, float]:
    """Each (non-closure) window's mid time in the plan's order and time model, seconds from its start."""
    out: dict[str, float] = {}
    t = 0.0
    for roi in plan.rois:
        if not getattr(roi, "closure", False):
            out.setdefault(roi.reflector, t + roi.expected_seconds / 2)
        t += roi.expected_seconds
    return out


def measure_fine(fine: Scan, plan: ScanPlan, layout: Layout | None = None, *,
                 profile: ScannerProfile | None = None) -> FineMeasurement:
    """Centroids (and closure centroids) of every planned target from the epoch's fine scans (concatenated)."""
    intensity = _need_intensity(fine, "the target centroids")
    diam = None if layout is None else {i: float(d) for i, d in zip(layout.ids, layout.diameters_m, strict=False)}
    times = getattr(fine, "time_s", None)
    cents, closures = measure_windows(fine.xyz_socs, intensity, plan.rois, diameters_m=diam,
                                      profile=profile or plan.profile, time_s=times)
    for rid, why in plan.skipped:  # not planned from this station: not found, and why
        cents.setdefault(rid, TargetCentroid(rid, np.full(3, np.nan), np.full((3, 3), np.nan), 0, float("nan"), 0.0,
                                             (FLAG_NOT_FOUND, f"{FLAG_UNRESOLVED}: {why}"), 0))
    if times is not None:
        return FineMeasurement(cents, closures, "points")
    t_plan = plan_times(plan)
    if not any(r.expected_seconds > 0 for r in plan.rois):
        return FineMeasurement(cents, {}, "none")
    timed = {k: replace(c, time_s=t_plan.get(k, float("nan"))) if c.found else c for k, c in cents.items()}
    return FineMeasurement(timed, {}, "plan")


def measure_targets(fine: Scan, plan: ScanPlan, layout: Layout | None = None, *,
                    profile: ScannerProfile | None = None) -> dict[str, TargetCentroid]:
    """Centroids of every planned target from the epoch's fine scans (concatenated; see :func:`measure_fine`)."""
    return dict(measure_fine(fine, plan, layout, profile=profile).centroids)

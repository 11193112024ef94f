"""The reflector pipeline end to end for one epoch: coarse scan -> plan -> fine scans -> centroids.

Each step is also available on its own in its module; these functions only chain them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

import numpy as np
from numpy.typing import ArrayLike

from lidar.centroid import TargetCentroid, centroids_from_scan
from lidar.detection import DetectionResult, detect_reflectors
from common.errors import InputError
from lidar.guided_detection import recover_predicted
from lidar.identification import MAX_TILT_DEG, Identification, identify_reflectors
from lidar.layout import Layout, target_normals
from lidar.plan import PlanTarget, ScanPlan, incidence_from_map, plan_fine_scans
from common.progress import ProgressCallback, report, scaled
from lidar.reflectance_map import ReflectanceMap, reflectance_map
from lidar.scan import Scan
from lidar.scanner_profile import VZ1000, ScannerProfile


@dataclass(frozen=True, eq=False)
class CoarseAnalysis:
    """What the coarse scan of an epoch tells: map, detections, identification, incidence per target."""

    reflectance_map: ReflectanceMap
    detections: DetectionResult
    identification: Identification
    incidence_cos: Mapping[str, Optional[float]]


def _need_intensity(scan: Scan, what: str) -> np.ndarray:
    """The scan's intensities; a scan without them is refused with what needs them."""
    if scan.intensity is None:
        raise InputError(f"{scan.source or scan.name}: the scan has no intensity values; {what} needs them "
                         "(export the scan with intensity/reflectance)")
    return scan.intensity


def analyse_coarse(scan: Scan, layout: Layout, *, step_deg: Optional[float] = None, threshold: Optional[float] = None,
                   tolerance_m: float = 0.15, max_tilt_deg: Optional[float] = MAX_TILT_DEG,
                   up_layout: ArrayLike = (0.0, 0.0, 1.0),
                   progress: Optional[ProgressCallback] = None) -> CoarseAnalysis:
    """Reflectance map, detection and identification of a coarse scan.

    ``max_tilt_deg`` and ``up_layout`` go to :func:`lidar.identification.identify_reflectors`
    (None for a scanner that was not levelled).
    """
    intensity = _need_intensity(scan, "reflector detection")
    rmap = reflectance_map(scan.xyz_socs, intensity, step_deg=step_deg, progress=scaled(progress, 0, 0.8))
    return analyse_map(rmap, layout, threshold=threshold, tolerance_m=tolerance_m, max_tilt_deg=max_tilt_deg,
                       up_layout=up_layout, progress=scaled(progress, 0.8, 1.0))


def analyse_map(rmap: ReflectanceMap, layout: Layout, *, threshold: Optional[float] = None,
                tolerance_m: float = 0.15, max_tilt_deg: Optional[float] = MAX_TILT_DEG,
                up_layout: ArrayLike = (0.0, 0.0, 1.0),
                progress: Optional[ProgressCallback] = None) -> CoarseAnalysis:
    """Detection and identification on a coarse scan's reflectance map (see :func:`analyse_coarse`)."""
    diameter = float(np.median(layout.diameters_m))
    det = detect_reflectors(rmap, target_diameter_m=diameter, threshold=threshold)
    report(progress, 0.5, "identifying reflectors")
    ident = identify_reflectors(det.xyz(), layout, tolerance_m=tolerance_m, max_tilt_deg=max_tilt_deg,
                                up_layout=up_layout)
    det, ident = recover_predicted(rmap, det, ident, tolerance_m=tolerance_m)
    inc = {m.id: incidence_from_map(rmap, m.xyz_socs) for m in ident.matches}
    report(progress, 1.0, "coarse scan analysed")
    return CoarseAnalysis(rmap, det, ident, inc)


def layout_incidence(identification: Identification, layout: Layout, *,
                     up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> dict[str, float]:
    """|cos| of the incidence angle at every identified target, from the layout's normals.

    The normals (``nx,ny,nz`` or the defaults of :func:`lidar.layout.target_normals`) are carried
    into the scanner frame by the rotation fitted to the detected targets; the viewing direction
    is the target's position (detected, or predicted from the layout). A target facing away from
    the scanner gets 0.
    """
    normals = target_normals(layout, up=up_layout)
    out = {}
    for m in identification.matches:
        n_socs = identification.rotation @ normals[layout.index(m.id)]
        xyz = np.asarray(m.xyz_socs, dtype=np.float64)
        view = -xyz / np.linalg.norm(xyz)
        out[m.id] = float(max(0.0, n_socs @ view))
    return out


def plan_from_coarse(coarse: CoarseAnalysis, layout: Layout, *, epoch: str = "", profile: ScannerProfile = VZ1000,
                     min_points: int = 1000, budget_seconds: float = 3600.0, margin_m: float = 0.10,
                     up_layout: ArrayLike = (0.0, 0.0, 1.0)) -> ScanPlan:
    """Fine-scan plan for every layout reflector (detected or predicted).

    Incidence comes from the layout's target normals carried into the scanner frame
    (:func:`layout_incidence`), for detected and predicted targets alike: the surface around a
    target in a coarse map is often another face (a pier corner, the deck edge).
    """
    inc = layout_incidence(coarse.identification, layout, up_layout=up_layout)
    targets = [PlanTarget(m.id, m.group, m.xyz_socs, float(layout.diameters_m[layout.index(m.id)]), m.predicted,
                          max(inc[m.id], 0.05)) for m in coarse.identification.matches]
    return plan_fine_scans(targets, epoch=epoch, profile=profile, min_points=min_points,
                           budget_seconds=budget_seconds, margin_m=margin_m)


def measure_targets(fine: Scan, plan: ScanPlan, layout: Optional[Layout] = None, *,
                    profile: Optional[ScannerProfile] = None) -> dict[str, TargetCentroid]:
    """Centroids of every planned target from the epoch's fine scans (concatenated)."""
    intensity = _need_intensity(fine, "the target centroids")
    diam = None if layout is None else {i: float(d) for i, d in zip(layout.ids, layout.diameters_m)}
    return centroids_from_scan(fine.xyz_socs, intensity, plan.rois, diameters_m=diam,
                               profile=profile or plan.profile)

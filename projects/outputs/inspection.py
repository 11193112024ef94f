"""What the desktop application shows of one epoch: a target's fine-scan window and a display cloud."""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from common.errors import InputError, ProcessingError
from common.progress import ProgressCallback, report, scaled
from lidar.angles import direction_from_angles, spherical_from_xyz
from lidar.centroid import TargetCentroid, target_centroid
from lidar.plan import RoiPlan
from projects.compare.whole_scan import compare_epochs, save_comparison
from projects.processing.stages import baseline_epoch, read_files
from projects.store.campaign import Campaign


@dataclass(frozen=True, eq=False)
class TargetInspection:
    """The points of one fine-scan window and how the centroid was found in them.

    ``theta_deg``, ``phi_deg``, ``intensity`` are (N,) over the window's points; ``bright``,
    ``cluster`` and ``disc`` are (N,) masks (above Otsu's threshold, the compact cluster kept,
    the points of the centroid); ``centroid`` is recomputed from these points and ``stored`` is
    what processing saved (None before processing).
    """

    epoch: str
    reflector: str
    roi: RoiPlan
    theta_deg: np.ndarray
    phi_deg: np.ndarray
    intensity: np.ndarray
    bright: np.ndarray
    cluster: np.ndarray
    disc: np.ndarray
    centroid: TargetCentroid
    stored: TargetCentroid | None
    diameter_m: float = 0.05

    def centroid_angles(self) -> tuple[float, float]:
        """(theta, phi) of the centroid, degrees (NaN when not found)."""
        if not self.centroid.found:
            return float("nan"), float("nan")
        t, p, _ = spherical_from_xyz(self.centroid.xyz_socs[None])
        return float(t[0]), float(p[0])


def inspect_target(c: Campaign, label: str, reflector: str, *,
                   progress: ProgressCallback | None = None) -> TargetInspection:
    """Read an epoch's fine scans and redo the centroid of ``reflector`` with its masks kept."""
    plan = c.plan(label)
    if plan is None:
        raise ProcessingError(f"epoch {label} has no plan yet; plan it first")
    roi = plan.roi(reflector)
    files = c.files(label, "fine")
    if not files:
        raise ProcessingError(f"epoch {label} has no fine scans yet; add them first")
    scan = read_files(c, files, scaled(progress, 0.0, 0.8), what="the inspection of a target")
    if scan.intensity is None:
        raise ProcessingError(f"the fine scans of {label} carry no intensity: the target cannot be told apart")
    theta, phi, _ = spherical_from_xyz(scan.xyz_socs)
    inside = roi.window.contains(theta, phi)
    if not inside.any():
        raise ProcessingError(f"the fine scans of {label} hold no point in the window of {reflector}")
    xyz = scan.xyz_socs[inside]
    inten = scan.intensity[inside].astype(np.float64)
    tc, pc = roi.window.centre
    diameter = c.reflector(reflector).diameter_m
    cent, trace = target_centroid(xyz, inten, reflector=reflector,
                                  expected_xyz=direction_from_angles(tc, pc) * roi.range_m,
                                  diameter_m=diameter, window=roi.window, profile=plan.profile, trace=True)
    report(progress, 1.0, "window read")
    return TargetInspection(label, reflector, roi, theta[inside].astype(np.float64), phi[inside].astype(np.float64),
                            inten, trace.bright, trace.cluster, trace.disc, cent,
                            c.centroids(label).get(reflector), float(diameter))


@dataclass(frozen=True, eq=False)
class DisplayCloud:
    """Points to draw (decimated for display only) with a value per point and labelled markers."""

    xyz: np.ndarray
    values: np.ndarray
    value_name: str
    n_total: int
    marker_ids: tuple
    marker_xyz: np.ndarray
    frame: str


def decimate(n: int, max_points: int, rng_seed: int = 0) -> np.ndarray:
    """Indices of at most ``max_points`` of ``n`` points, random but repeatable."""
    if n <= max_points:
        return np.arange(n)
    return np.sort(np.random.default_rng(rng_seed).choice(n, max_points, replace=False))


def around_targets(xyz: np.ndarray, targets: np.ndarray, margin_m: float) -> np.ndarray:
    """Mask of the points within ``margin_m`` of the targets' bounding box (all points without targets)."""
    if not len(targets):
        return np.ones(len(xyz), bool)
    lo, hi = targets.min(axis=0) - margin_m, targets.max(axis=0) + margin_m
    lo[2] -= margin_m  # the ground below the bridge
    return np.all((xyz >= lo) & (xyz <= hi), axis=1)


def epoch_cloud(c: Campaign, label: str, *, max_points: int = 1_500_000, margin_m: float | None = 15.0,
                progress: ProgressCallback | None = None) -> DisplayCloud:
    """An epoch's coarse scan coloured by intensity, with its targets (centroids, else the plan's).

    ``margin_m``: show the bridge and this much around its targets (None: the whole scan).
    """
    c.epoch(label)
    files = c.files(label, "coarse")
    if not files:
        raise InputError(f"epoch {label} has no coarse scan")
    scan = read_files(c, files, scaled(progress, 0.0, 0.9), what="the 3-D view")
    if scan.intensity is None:
        raise InputError(f"the coarse scan of {label} carries no intensity to colour it by")
    ids, xyz = _targets_of(c, label)
    near = np.nonzero(around_targets(scan.xyz_socs, xyz, margin_m))[0] if margin_m is not None \
        else np.arange(len(scan.xyz_socs))
    keep = near[decimate(len(near), max_points)]
    report(progress, 1.0, "cloud ready")
    part = "" if len(near) == len(scan.xyz_socs) else f", within {margin_m:g} m of the targets"
    return DisplayCloud(scan.xyz_socs[keep], scan.intensity[keep].astype(np.float32), "intensity",
                        len(scan.xyz_socs), ids, xyz, f"scanner frame of {label}{part}")


def _targets_of(c: Campaign, label: str) -> tuple[tuple, np.ndarray]:
    cents = {k: v for k, v in c.centroids(label).items() if v.found}
    if cents:
        return tuple(cents), np.array([v.xyz_socs for v in cents.values()])
    plan = c.plan(label)
    if plan is None:
        return (), np.zeros((0, 3))
    pts = [direction_from_angles(*r.window.centre) * r.range_m for r in plan.rois]
    return tuple(r.reflector for r in plan.rois), np.array(pts).reshape(-1, 3)


def change_against_baseline(folder: str | os.PathLike, label: str, *,
                            progress: ProgressCallback | None = None) -> DisplayCloud:
    """:func:`change_cloud` of ``label`` against the campaign's baseline, the comparison saved; paths in, cloud out.

    A function of paths only, so that it can run in a process of its own (:func:`common.processes.run_in_process`:
    the desktop application's 3-D change, whose search trees are built in compiled code that holds Python's lock).
    """
    with Campaign.open(folder, writable=True) as c:
        base = baseline_epoch(c)
        if base is None:
            raise InputError("no processed epoch yet to compare against; process the campaign first")
        if base == label:
            raise InputError(f"{label} is the baseline epoch; select another epoch to see its change")
        cloud, summary = change_cloud(c, base, label, progress=progress)
        save_comparison(c, summary)
        return cloud


def change_cloud(c: Campaign, base: str, label: str, *, max_points: int = 1_500_000,
                 progress: ProgressCallback | None = None) -> tuple[DisplayCloud, dict]:
    """M3C2 change (mm, signed) of ``label`` against ``base`` in the campaign frame, and the summary."""
    summary = compare_epochs(c, base, label, method="m3c2", progress=scaled(progress, 0.0, 0.95))
    ch = summary.pop("_arrays")["change"]
    keep = decimate(len(ch.points), max_points)
    ids, xyz = _targets_of(c, summary["baseline"])  # the baseline's scanner frame is the campaign frame
    report(progress, 1.0, "change ready")
    return DisplayCloud(ch.points[keep], (ch.distance_m[keep] * 1e3).astype(np.float32),
                        "M3C2 change (mm)", len(ch.points), ids, xyz,
                        f"M3C2 change {base} → {label} at core points, campaign frame ({summary['baseline']})"), summary

"""Where to stand: predicted displacement uncertainty of every target from a candidate scanner position.

For a levelled scanner at a position of the layout's frame, each target's range, zenith angle and
incidence (from the layout's normals) give the fine-scan plan the planner would make
(:func:`lidar.plan.plan_fine_scans`, same instrument, same points and time budget), hence the points
on each target and its centroid covariance (:mod:`lidar.prediction`). Those covariances go through
the very computation that processing runs (:func:`lidar.systematic.budget.corrected_displacements`), against
the baseline's stored centroids when there is a baseline, so the predicted sigma is the one
processing would report.

Visibility is judged from the layout: a target is hidden when it faces away from the station, lies
outside the instrument's vertical field of view or range, or when a pier (the plane of a group of
reference targets, up to the deck) stands between it and the station.
"""
from __future__ import annotations

import logging
import math
import os
from collections.abc import Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from multiprocessing import get_context
from pickle import PicklingError
from typing import Any

import numpy as np
from matplotlib.path import Path as MplPath
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from common.errors import InputError, SurveyError
from common.progress import ProgressCallback, report
from common.rigid import fit_rigid
from lidar.layout import Layout, bridge_axis, target_normals
from lidar.pipeline import plan_times
from lidar.plan import PlanTarget, coarse_step_needed_deg, plan_fine_scans
from lidar.prediction import centroid_covariance
from lidar.scanner_profile import ScannerProfile
from lidar.systematic.adjustment import FieldModel, VisitSystematics
from lidar.systematic.budget import corrected_displacements
from lidar.systematic.range_walk import RangeWalkModel
from lidar.visit_plan import SetupTargets, VisitPlan, plan_visit

log = logging.getLogger(__name__)
MIN_INCIDENCE_COS = 0.1  # beyond about 84 deg a retro-reflective disc returns too few points to use


@dataclass(frozen=True)
class StationPrediction:
    """What a fine-scan visit from one position would deliver.

    Attributes
    ----------
    xyz_layout : (3,) tuple
        Scanner origin in the layout's frame, metres.
    seconds : float
        Time of the fine scans the planner would make.
    predicted_sigma_mm : mapping id -> float
        Predicted standard deviation of each visible measurement target's vertical displacement, mm.
    hidden : tuple of str
        Targets the station cannot measure, with ``reasons`` saying why.
    points : mapping id -> int
        Points the plan would put on each visible target.
    weak : tuple of str
        Targets measured only at grazing incidence from here (narrower than
        :data:`lidar.centroid.WEAK_RATIO` of the beam): planned in the time left, with a widened sigma.
        Those narrower than :data:`lidar.centroid.UNRESOLVED_RATIO` are in ``hidden`` ("not measured").
    coarse_step_deg : float
        The coarsest coarse-scan step that resolves every target the plan would measure well from here (the
        weak ones' windows come from the layout; :func:`lidar.plan.coarse_step_needed_deg`; NaN when none),
        degrees.
    """

    xyz_layout: tuple[float, ...]
    seconds: float
    predicted_sigma_mm: Mapping[str, float]
    hidden: tuple[str, ...]
    points: Mapping[str, int] = field(default_factory=dict)
    reasons: Mapping[str, str] = field(default_factory=dict)
    usable: bool = True
    weak: tuple[str, ...] = ()
    coarse_step_deg: float = float("nan")

    @property
    def worst_sigma_mm(self) -> float:
        """Largest predicted sigma (inf when no displacement can be computed)."""
        if not self.usable or not self.predicted_sigma_mm:
            return math.inf
        return max(self.predicted_sigma_mm.values())

    def rank_key(self) -> tuple:
        return (not self.usable, len(self.hidden), self.worst_sigma_mm, self.seconds, self.xyz_layout)

    def to_json(self) -> dict:
        worst = self.worst_sigma_mm
        x, y, z = (round(float(v), 3) for v in self.xyz_layout)
        return {"x": x, "y": y, "z": z,
                "seconds": round(float(self.seconds), 1),
                "worst_sigma_mm": None if math.isinf(worst) else round(float(worst), 4),
                "predicted_sigma_mm": {k: round(float(v), 4) for k, v in self.predicted_sigma_mm.items()},
                "hidden": list(self.hidden), "hidden_reasons": dict(self.reasons),
                "weak": list(self.weak), "points": dict(self.points),
                "coarse_step_deg": None if not math.isfinite(self.coarse_step_deg) else round(self.coarse_step_deg, 4)}


def _level_rotation(up: np.ndarray) -> np.ndarray:
    """Rotation taking layout vectors into a levelled scanner frame (+z along ``up``)."""
    z = up / np.linalg.norm(up)
    hint = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = hint - (hint @ z) * z
    x /= np.linalg.norm(x)
    return np.vstack([x, np.cross(z, x), z])


@dataclass(frozen=True)
class _Piers:
    """Piers as vertical planes across the bridge at the reference targets' along-span positions."""

    axis: np.ndarray
    across: np.ndarray
    up: np.ndarray
    along: tuple[float, ...]
    across_extent: tuple[float, float]
    top: float

    @classmethod
    def from_layout(cls, layout: Layout, up: np.ndarray) -> _Piers:
        axis = bridge_axis(layout, up=up)
        across = np.cross(up, axis)
        ref = np.array([g == "reference" for g in layout.groups])
        a = np.sort(layout.xyz[ref] @ axis)
        groups: list[list[float]] = []
        for v in a:
            if groups and v - groups[-1][-1] < 2.0:
                groups[-1].append(v)
            else:
                groups.append([v])
        c = layout.xyz @ across
        meas = ~ref
        top = float(np.median(layout.xyz[meas] @ up)) if np.any(meas) else float(np.max(layout.xyz @ up))
        return cls(axis, across, up, tuple(float(np.mean(g)) for g in groups),
                   (float(c.min()) - 1.0, float(c.max()) + 1.0), top)

    def blocks(self, station: np.ndarray, target: np.ndarray) -> bool:
        a0, a1 = station @ self.axis, target @ self.axis
        for a in self.along:
            if min(a0, a1) + 0.5 < a < max(a0, a1) - 0.5:
                f = (a - a0) / (a1 - a0)
                p = station + f * (target - station)
                if self.across_extent[0] <= p @ self.across <= self.across_extent[1] and p @ self.up < self.top:
                    return True
        return False


class Obstacles:
    """Surfaces a previous scan saw, in the layout's frame: a line of sight passing through them is blocked.

    Parameters
    ----------
    xyz_layout : (M, 3) array
        Scan points carried into the layout's frame (decimated to a few centimetres is plenty).
    radius_m : float
        How close to the line of sight a point must be to block it. Default 0.03 m.
    """

    def __init__(self, xyz_layout: np.ndarray, *, radius_m: float = 0.03):
        pts = np.asarray(xyz_layout, dtype=np.float64).reshape(-1, 3)
        self.radius_m = float(radius_m)
        self.tree = cKDTree(pts[np.all(np.isfinite(pts), axis=1)]) if len(pts) else None

    def blocks(self, station: np.ndarray, target: np.ndarray, *, clear_start_m: float = 0.5,
               clear_end_m: float = 0.3) -> bool:
        """Whether at least two samples of the segment (apart from its ends) lie on a seen surface."""
        if self.tree is None:
            return False
        d = target - station
        length = float(np.linalg.norm(d))
        if length <= clear_start_m + clear_end_m:
            return False
        u = d / length
        f = np.arange(clear_start_m, length - clear_end_m, self.radius_m * 1.5)
        samples = station + f[:, None] * u
        dist, _ = self.tree.query(samples, distance_upper_bound=self.radius_m)
        return int(np.count_nonzero(np.isfinite(dist))) >= 2


@dataclass(frozen=True, eq=False)
class _Sighted:
    """A centroid as the displacement budget reads it (position, covariance, incidence, time)."""

    xyz_socs: np.ndarray
    cov: np.ndarray
    cos_incidence: float = float("nan")
    time_s: float = float("nan")


def _as_sighted(o: Any) -> _Sighted:
    xyz = getattr(o, "xyz_socs", None)
    if xyz is None:
        xyz = o.xyz
    return _Sighted(np.asarray(xyz, dtype=np.float64), np.asarray(o.cov, dtype=np.float64),
                    float(getattr(o, "cos_incidence", float("nan"))), float(getattr(o, "time_s", float("nan"))))


def _typical_visit(field: FieldModel, label: str) -> VisitSystematics:
    """A visit as the campaign's visits have been: their median scale sigma, drift covariance and misfit.

    Each of the range walk's families implies its own scale for a visit; the typical visit's departs from its
    scale (0 here) by the median of what it did in the other visits.
    """
    others = [v for k, v in field.visits.items() if k != field.baseline] or list(field.visits.values())
    if not others:
        return VisitSystematics(label)
    timed = [v for v in others if v.timed]
    drift = np.median([v.drift_cov for v in timed], axis=0) if timed else np.zeros((3, 3))
    n_alt = len(field.range_walk.alternatives)
    alt_scales = [np.asarray(v.alternative_scale_ppm) - v.scale_ppm for v in others
                  if n_alt and len(v.alternative_scale_ppm) == n_alt]
    alternative = tuple(float(x) for x in np.median(alt_scales, axis=0)) if alt_scales else ()
    return VisitSystematics(label, 0.0, float(np.median([v.scale_sigma_ppm for v in others])), np.zeros(3), drift,
                            0.0, bool(timed), True, (), alternative, float(np.median([v.misfit for v in others])))


def station_targets(layout: Layout, station_layout: ArrayLike, *, profile: ScannerProfile,
                    up: ArrayLike = (0.0, 0.0, 1.0), normals: np.ndarray | None = None, piers: _Piers | None = None,
                    obstacles: Obstacles | None = None
                    ) -> tuple[list[PlanTarget], dict[str, str], dict[str, np.ndarray]]:
    """The targets a levelled scanner at ``station_layout`` would plan, in its frame (x along the layout's x).

    Returns the plan targets (the hidden ones left out), why each hidden target is hidden (facing away, grazing,
    outside the field of view, beyond the range, behind a pier or something the last scan saw), and each plan
    target's normal in the scanner frame. The heading is the layout's: the windows' azimuths differ on site, their
    ranges, incidences, points and times do not.
    """
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    s = np.asarray(station_layout, dtype=np.float64)
    if s.shape != (3,) or not np.all(np.isfinite(s)):
        raise InputError(f"a station must be three finite coordinates, got {station_layout!r}")
    rot = _level_rotation(u)
    normals = target_normals(layout, up=u) if normals is None else normals
    piers = piers or _Piers.from_layout(layout, u)
    lo, hi = profile.theta_fov_deg
    reasons: dict[str, str] = {}
    targets: list[PlanTarget] = []
    normal_socs: dict[str, np.ndarray] = {}
    for k, tid in enumerate(layout.ids):
        x = rot @ (layout.xyz[k] - s)
        r = float(np.linalg.norm(x))
        n_s = rot @ normals[k]
        cos_inc = float(n_s @ (-x / r))
        theta = math.degrees(math.acos(np.clip(x[2] / r, -1.0, 1.0)))
        why = None
        if cos_inc < MIN_INCIDENCE_COS:
            why = "faces away" if cos_inc <= 0 else f"grazing ({math.degrees(math.acos(cos_inc)):.0f} deg incidence)"
        elif not lo <= theta <= hi:
            why = f"outside the vertical field of view (zenith {theta:.0f} deg)"
        elif r > profile.max_range_m:
            why = f"beyond the range ({r:.0f} m)"
        elif piers.blocks(s, layout.xyz[k]):
            why = "behind a pier"
        elif obstacles is not None and obstacles.blocks(s, layout.xyz[k]):
            why = "behind something the last scan saw"
        if why:
            reasons[tid] = why
            continue
        targets.append(PlanTarget(tid, layout.groups[k], tuple(x), float(layout.diameters_m[k]), False, cos_inc))
        normal_socs[tid] = n_s
    return targets, reasons, normal_socs


def plan_visit_from_positions(layout: Layout, positions_layout: Sequence[Sequence[float]], *,
                              profile: ScannerProfile, min_points: int = 1000, budget_seconds: float = 3600.0,
                              up: ArrayLike = (0.0, 0.0, 1.0), closure: bool = False,
                              obstacles: Obstacles | None = None, reference_factor: float = 1.0) -> VisitPlan:
    """A visit's set-ups planned together from their planned positions alone, before any coarse scan.

    Each position's targets are those a levelled scanner there would plan (:func:`station_targets`, with their
    normals); the set-ups are then planned as on site (:func:`lidar.visit_plan.plan_visit`): which set-up measures
    which target, the ties that join them, each one's share of the visit's budget. Set-up k stands at the k-th
    position. On site the plans are made again from the coarse scans (the heading and the exact place differ).
    """
    u = np.asarray(up, dtype=np.float64)
    normals = target_normals(layout, up=u / np.linalg.norm(u))
    piers = _Piers.from_layout(layout, u / np.linalg.norm(u))
    setups = []
    for k, pos in enumerate(positions_layout, start=1):
        targets, _, n_socs = station_targets(layout, pos, profile=profile, up=u, normals=normals, piers=piers,
                                             obstacles=obstacles)
        setups.append(SetupTargets(k, tuple(replace(t, normal_socs=tuple(float(v) for v in n_socs[t.id]))
                                            for t in targets), profile))
    return plan_visit(setups, min_points=min_points, budget_seconds=budget_seconds, closure=closure,
                      reference_factor=reference_factor)


def predict_station(layout: Layout, station_layout: Sequence[float], *, profile: ScannerProfile,
                    min_points: int = 1000, budget_seconds: float = 3600.0, up: ArrayLike = (0.0, 0.0, 1.0),
                    baseline: Mapping[str, object] | None = None,
                    normals: np.ndarray | None = None, piers: _Piers | None = None,
                    obstacles: Obstacles | None = None, field_model: FieldModel | None = None,
                    closure: bool = False, reference_factor: float = 1.0) -> StationPrediction:
    """Predicted plan time, points and displacement sigma of every target from one station.

    Parameters
    ----------
    layout : Layout
    station_layout : (3,) sequence
        Scanner origin in the layout's frame, metres.
    profile : ScannerProfile, keyword-only
    min_points, budget_seconds : keyword-only
        The planner's settings (the campaign's ``min_points`` and ``budget_min``).
    up : (3,), keyword-only
        The layout's up axis.
    baseline : mapping id -> centroid, optional, keyword-only
        The baseline epoch's centroids (its own scanner frame). Default: a baseline taken from
        this same station (same covariances, independent noise).
    normals : (N, 3) array, optional, keyword-only
        Target normals in the layout frame (default :func:`lidar.layout.target_normals`).
    obstacles : Obstacles, optional, keyword-only
        Surfaces a previous scan saw (the last epoch's coarse scan): lines of sight through them are blocked.
    field_model : FieldModel, optional, keyword-only
        The campaign's field model (:mod:`lidar.systematic`): the prediction then carries the terms processing
        adds (the range walk's uncertainty at this station's ranges and incidences, a typical visit's scale,
        drift over this plan's duration and misfit), so a station that leaves them large ranks lower.
    closure : bool, keyword-only
        Plan a closure window, as processing does (default False).
    reference_factor : float, keyword-only
        The reference targets' factor of points, as processing plans it (the campaign's ``reference_points_factor``;
        default 1).
    """
    s = np.asarray(station_layout, dtype=np.float64)
    targets, reasons, normal_socs = station_targets(layout, s, profile=profile, up=up, normals=normals, piers=piers,
                                                    obstacles=obstacles)
    hidden = list(reasons)
    if not targets:
        return StationPrediction(tuple(float(v) for v in s), 0.0, {}, tuple(hidden), {}, reasons, usable=False)
    plan = plan_fine_scans(targets, profile=profile, min_points=min_points, budget_seconds=budget_seconds,
                           closure=closure, reference_factor=reference_factor)
    times = plan_times(plan)
    for tid, why in plan.skipped:  # narrower than the beam, or weak with no time left: not measured from here
        hidden.append(tid)
        reasons[tid] = f"not measured: {why}"
    weak = tuple(r.reflector for r in plan.rois if not r.closure and any(n.startswith("weak:") for n in r.notes))
    planned = {r.reflector for r in plan.rois} - set(weak)  # a weak target's window comes from the layout anyway
    step = min((coarse_step_needed_deg(t.diameter_m, t.incidence_cos or 1.0, float(np.linalg.norm(t.xyz_socs)))
                for t in targets if t.id in planned), default=float("nan"))
    epoch, points = {}, {}
    by_id = {t.id: t for t in targets}
    for roi in plan.rois:
        t = by_id[roi.reflector]
        if roi.closure or t.id in epoch:
            continue
        n = max(roi.expected_target_points, 1)
        points[t.id] = int(n)
        epoch[t.id] = _Sighted(np.asarray(t.xyz_socs), centroid_covariance(
            t.xyz_socs, normal_socs[t.id], n, diameter_m=t.diameter_m, range_noise_m=profile.range_noise_m,
            profile=profile),
            float(t.incidence_cos or 1.0), times.get(t.id, float("nan")))
    base = {k: _as_sighted(v) for k, v in baseline.items()} if baseline is not None else dict(epoch)
    if baseline is not None:  # same geometry as the baseline: positions from it, so nothing looks moved
        carried = _carry(base, epoch)
        epoch = {k: replace(o, xyz_socs=carried.get(k, o.xyz_socs)) for k, o in epoch.items()}
    groups = dict(zip(layout.ids, layout.groups, strict=False))
    model = field_model if field_model is not None and baseline is not None else FieldModel("__baseline__", RangeWalkModel(), {})
    label = "__station__"
    model = replace(model, visits={**dict(model.visits), label: _typical_visit(model, label)})
    try:
        res = corrected_displacements(base, epoch, groups, model=model, baseline_label=model.baseline,
                                      epoch_label=label, expected_sigmas=True)
    except SurveyError:
        return StationPrediction(tuple(float(v) for v in s), plan.total_seconds, {}, tuple(hidden), points, reasons,
                                 usable=False, weak=weak, coarse_step_deg=step)
    sig = {d.reflector: d.sigma_m * 1000.0 for d in res.displacements if np.isfinite(d.sigma_m)}
    return StationPrediction(tuple(float(v) for v in s), plan.total_seconds, sig, tuple(hidden), points, reasons,
                             usable=bool(sig), weak=weak, coarse_step_deg=step)


def _carry(base: Mapping[str, _Sighted], epoch: Mapping[str, _Sighted]) -> dict[str, np.ndarray]:
    """Epoch positions such that the epoch is the baseline seen from the station (no change).

    A rigid fit of the shared targets carries the baseline positions into the station's frame.
    """
    shared = [i for i in epoch if i in base]
    if len(shared) < 3:
        return {}
    motion = fit_rigid(np.array([base[i].xyz_socs for i in shared]), np.array([epoch[i].xyz_socs for i in shared]))
    return {k: motion.apply(np.asarray(base[k].xyz_socs)) for k in shared}


def default_area(layout: Layout, *, up: ArrayLike = (0.0, 0.0, 1.0), reach_m: float = 25.0,
                 beyond_m: float = 5.0) -> np.ndarray:
    """(4, 2) polygon in the layout's x, y where stations are tried.

    A band ``reach_m`` to both sides of the bridge, from ``beyond_m`` before the first pier target to ``beyond_m``
    after the last.
    """
    u = np.asarray(up, dtype=np.float64)
    axis = bridge_axis(layout, up=u)
    across = np.cross(u / np.linalg.norm(u), axis)
    a = layout.xyz @ axis
    c = layout.xyz @ across
    c0 = 0.5 * (c.min() + c.max())
    lo, hi = a.min() - beyond_m, a.max() + beyond_m
    corners = [lo * axis + (c0 - reach_m) * across, hi * axis + (c0 - reach_m) * across,
               hi * axis + (c0 + reach_m) * across, lo * axis + (c0 + reach_m) * across]
    return np.array([[p[0], p[1]] for p in corners])


def grid_in_polygon(polygon_xy: np.ndarray, grid_m: float) -> np.ndarray:
    """(M, 2) grid points (spacing ``grid_m``) inside a polygon of (K, 2) vertices."""
    poly = np.asarray(polygon_xy, dtype=np.float64)
    if poly.ndim != 2 or poly.shape[1] != 2 or len(poly) < 3 or not np.all(np.isfinite(poly)):
        raise InputError("the allowed area needs at least 3 finite x,y vertices")
    if not grid_m > 0:
        raise InputError(f"the grid spacing must be positive, got {grid_m}")
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    n = np.prod(np.floor((hi - lo) / grid_m) + 1)
    if n > 200_000:
        raise InputError(f"a {grid_m:g} m grid over this area has {int(n):,} positions; use a coarser --grid-m")
    xs = np.arange(lo[0] + grid_m / 2, hi[0], grid_m)
    ys = np.arange(lo[1] + grid_m / 2, hi[1], grid_m)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    inside = MplPath(poly).contains_points(pts)
    return pts[inside]


def _predict_chunk(args, each=None) -> list[StationPrediction]:
    layout, positions, kwargs = args
    kwargs = dict(kwargs)
    u = np.asarray(kwargs["up"], dtype=np.float64)
    normals = target_normals(layout, up=u)
    piers = _Piers.from_layout(layout, u)
    seen = kwargs.pop("obstacles_xyz", None)
    obstacles = Obstacles(seen) if seen is not None else None
    out = []
    for p in positions:
        out.append(predict_station(layout, p, normals=normals, piers=piers, obstacles=obstacles, **kwargs))
        if each is not None:
            each(len(out))  # in this process only: the progress callback, which may cancel
    return out


def _terminate_workers(ex) -> None:
    """Stop a process pool's workers now (a cancelled survey), instead of letting their chunks finish."""
    procs = list((getattr(ex, "_processes", None) or {}).values())  # before shutdown forgets them
    ex.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.terminate()


def survey_stations(layout: Layout, positions_layout: np.ndarray, *, profile: ScannerProfile,
                    min_points: int = 1000, budget_seconds: float = 3600.0, up: ArrayLike = (0.0, 0.0, 1.0),
                    baseline: Mapping[str, object] | None = None, workers: int | None = None,
                    obstacles_xyz: np.ndarray | None = None, field_model: FieldModel | None = None,
                    closure: bool = False, reference_factor: float = 1.0,
                    progress: ProgressCallback | None = None) -> tuple[StationPrediction, ...]:
    """:func:`predict_station` at every position of an (M, 3) array, best first.

    ``workers`` processes share the positions (default: one per core, at most 4; 1 runs here).
    ``obstacles_xyz`` are scan points in the layout frame (see :class:`Obstacles`).
    Each station costs about 0.1-0.2 s (the displacement uncertainty is propagated exactly as
    processing does), so a 600-position grid takes about half a minute on two cores.
    """
    pos = np.asarray(positions_layout, dtype=np.float64).reshape(-1, 3)
    if len(pos) == 0:
        raise InputError("no candidate station: the allowed area holds no grid position")
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    kwargs = dict(profile=profile, min_points=min_points, budget_seconds=budget_seconds, up=u, baseline=baseline,
                  field_model=field_model, closure=closure, reference_factor=reference_factor)
    if obstacles_xyz is not None:
        kwargs["obstacles_xyz"] = np.asarray(obstacles_xyz, dtype=np.float32).reshape(-1, 3)
    n_workers = min(4, os.cpu_count() or 1) if workers is None else max(1, int(workers))
    chunk = 24
    jobs = [(layout, pos[i:i + chunk], kwargs) for i in range(0, len(pos), chunk)]
    out: list[StationPrediction] = []
    if n_workers > 1 and len(jobs) >= 3:
        try:
            # spawn, not fork: this may run in a GUI worker thread, where forking is unsafe
            ex = ProcessPoolExecutor(n_workers, mp_context=get_context("spawn"))
        except (OSError, RuntimeError) as exc:
            log.info("station survey without worker processes (%s)", exc)
        else:
            try:
                pending = {ex.submit(_predict_chunk, job) for job in jobs}
                while pending:
                    # a progress call at least every 0.25 s: the callback may cancel, and then it stops at once
                    done, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
                    for f in done:
                        out.extend(f.result())
                    report(progress, len(out) / len(pos), f"{len(out)} of {len(pos)} stations")
            except (OSError, RuntimeError, BrokenProcessPool, PicklingError) as exc:
                # no worker processes here (a frozen or embedded interpreter, a script without a main guard):
                # the same work in this process
                log.info("station survey without worker processes (%s)", exc)
                ex.shutdown(wait=False, cancel_futures=True)
                out = []
            except BaseException:
                _terminate_workers(ex)  # cancelled (or interrupted): do not wait for the chunks under way
                raise
            else:
                ex.shutdown(wait=True)
    if len(out) < len(pos):
        out = []
        for job in jobs:
            before = len(out)
            out.extend(_predict_chunk(job, each=lambda n, before=before: report(
                progress, (before + n) / len(pos), f"{before + n} of {len(pos)} stations")))
    report(progress, 1.0, "stations evaluated")
    return tuple(sorted(out, key=StationPrediction.rank_key))

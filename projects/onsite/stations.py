"""Station advice for a campaign: where to set up next visit, from the layout and the baseline.

Wraps :mod:`lidar.stations` with what the campaign knows: its scanner, planner settings, layout up
axis, the baseline's centroids, and the ground height (from the last measured station).
"""
from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from common.arrays import thin_to_voxels
from common.errors import InputError
from common.files import write_atomic
from common.progress import ProgressCallback, report, scaled
from common.rigid import fit_rigid
from lidar.stations import StationPrediction, default_area, grid_in_polygon, plan_visit_from_positions, survey_stations
from lidar.visit_plan import VisitPlan
from projects.processing.parameters import visit_budget_seconds
from projects.processing.stages import baseline_epoch, layout_up, parameters, read_files
from projects.store.campaign import Campaign

STATIONS_FORMAT_VERSION = 1
DEFAULT_INSTRUMENT_HEIGHT_M = 1.5


@dataclass(frozen=True)
class StationAdvice:
    """Candidate stations of a campaign, best first, with how they were evaluated."""

    stations: tuple[StationPrediction, ...]
    area_xy: np.ndarray
    ground_z: float
    ground_source: str
    height_m: float
    grid_m: float
    scanner: str
    baseline: str | None
    last_station: tuple[float, float, float] | None
    obstacles_from: str | None = None

    def to_json(self) -> dict:
        return {"format_version": STATIONS_FORMAT_VERSION, "frame": "layout", "scanner": self.scanner,
                "baseline": self.baseline, "ground_z": round(self.ground_z, 3), "ground_source": self.ground_source,
                "height_m": self.height_m, "grid_m": self.grid_m,
                "area": [[float(x), float(y)] for x, y in self.area_xy],
                "last_station": None if self.last_station is None else [round(v, 3) for v in self.last_station],
                "visibility": "from the layout (target normals, the instrument's field of view and range, piers "
                              "between the station and the target)" + (
                                  f" and the surfaces epoch {self.obstacles_from}'s coarse scan saw"
                                  if self.obstacles_from else "; obstacles the layout does not know are not seen"),
                "stations": [s.to_json() for s in self.stations]}

    def save(self, path: str | os.PathLike) -> Path:
        return write_atomic(path, json.dumps(self.to_json(), indent=1))


def read_area_csv(path: str | os.PathLike) -> np.ndarray:
    """(K, 2) polygon vertices from ``area.csv`` (columns ``x,y``, layout frame)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: area file not found")
    try:
        rows = list(csv.DictReader(p.read_text(encoding="utf-8-sig").splitlines()))
    except (UnicodeDecodeError, OSError) as exc:
        raise InputError(f"{p}: cannot read the area as text ({exc})") from None
    pts = []
    for k, row in enumerate(rows, start=2):
        row = {(a or "").strip().lower(): (b or "").strip() for a, b in row.items()}
        if "x" not in row or "y" not in row:
            raise InputError(f"{p}: the area needs columns x,y (polygon vertices in the layout's frame)")
        try:
            xy = (float(row["x"]), float(row["y"]))
        except ValueError:
            raise InputError(f"{p}, line {k}: x and y must be numbers") from None
        if not np.all(np.isfinite(xy)):
            raise InputError(f"{p}, line {k}: x and y must be finite")
        pts.append(xy)
    if len(pts) < 3:
        raise InputError(f"{p}: the area needs at least 3 vertices, found {len(pts)}")
    return np.array(pts)


@dataclass(frozen=True)
class LastStation:
    """Where the last measured epoch's scanner stood.

    Its frame is ``rotation @ layout + translation``
    (rigid fit of its found centroids to the layout).
    """

    label: str
    rotation: np.ndarray
    translation: np.ndarray

    @property
    def position_layout(self) -> np.ndarray:
        return self.rotation.T @ (-self.translation)


def last_station(c: Campaign) -> LastStation | None:
    """The last epoch with at least three found targets, and its station (None before any)."""
    for e in reversed(c.epochs()):
        cents = {k: v for k, v in c.centroids(e.label).items() if v.found}
        layout = c.layout(e.datetime)
        ids = [i for i in layout.ids if i in cents]
        if len(ids) < 3:
            continue
        pose = fit_rigid(np.array([layout.xyz[layout.index(i)] for i in ids]),
                         np.array([cents[i].xyz_socs for i in ids]), source_frame="layout",
                         target_frame=f"socs:{e.label}")
        return LastStation(e.label, pose.rotation, pose.translation)
    return None


def seen_surfaces(c: Campaign, last: LastStation, *, voxel_m: float = 0.05,
                  progress: ProgressCallback | None = None) -> np.ndarray | None:
    """The epoch's coarse scan in the layout's frame, one point per ``voxel_m`` cube (None without one)."""
    if not c.files(last.label, "coarse"):
        return None
    scan = read_files(c, c.files(last.label, "coarse"), scaled(progress, 0.0, 0.8),
                      what="the station advisor")
    report(progress, 0.8, "the scan's surfaces as obstacles")  # (a cancel stops here, before the voxels)
    xyz = (scan.xyz_socs - last.translation) @ last.rotation  # R^T (x - t), row-wise
    return thin_to_voxels(xyz, voxel_m).astype(np.float32)


def advise_stations(c: Campaign, *, area_xy: np.ndarray | None = None, height_m: float = DEFAULT_INSTRUMENT_HEIGHT_M,
                    grid_m: float = 2.0, ground_z: float | None = None, use_last_scan: bool = True,
                    also_xy: tuple[float, float] | None = None,
                    progress: ProgressCallback | None = None) -> StationAdvice:
    """Evaluate scanner positions on a grid inside the allowed area (default: both sides of the bridge).

    ``also_xy`` adds one position (layout frame) to the grid, wherever it is: where set-up 1 will stand.

    With ``use_last_scan`` the last measured epoch's coarse scan adds what it saw (vegetation, site
    huts, the deck's own edges) as obstacles to the lines of sight.
    """
    if not (np.isfinite(height_m) and 0 < height_m < 50):
        raise InputError(f"the instrument height must be between 0 and 50 m, got {height_m}")
    params = parameters(c)
    up = layout_up(params)
    layout = c.layout()
    area = default_area(layout, up=up) if area_xy is None else np.asarray(area_xy, dtype=np.float64)
    grid = grid_in_polygon(area, grid_m)
    if also_xy is not None:
        grid = np.vstack([grid.reshape(-1, 2), np.asarray(also_xy, dtype=np.float64).reshape(1, 2)])
    last = last_station(c)
    station = None if last is None else last.position_layout
    if ground_z is not None:
        gz, source = float(ground_z), "given"
    elif station is not None and last is not None:
        gz, source = float(station[2]) - DEFAULT_INSTRUMENT_HEIGHT_M, \
            f"epoch {last.label}'s station minus {DEFAULT_INSTRUMENT_HEIGHT_M} m"
    else:
        gz, source = 0.0, "assumed 0 (no measured epoch yet; pass --ground-z)"
    positions = np.column_stack([grid, np.full(len(grid), gz + height_m)])
    base_label = baseline_epoch(c)
    baseline = None
    if base_label is not None:
        baseline = {k: v for k, v in c.centroids(base_label).items() if v.found} or None
    seen = seen_surfaces(c, last, progress=scaled(progress, 0.0, 0.2)) if use_last_scan and last else None
    seen_label = None if seen is None or last is None else last.label
    stations = survey_stations(layout, positions, profile=c.profile, min_points=int(params["min_points"]),
                               budget_seconds=float(params["budget_min"]) * 60.0, up=up, baseline=baseline,
                               obstacles_xyz=seen, field_model=_field_model(c, params),
                               closure=bool(params["closure"]),
                               reference_factor=float(params["reference_points_factor"]),
                               progress=scaled(progress, 0.2, 1.0))
    return StationAdvice(stations, area, gz, source, float(height_m), float(grid_m), c.profile.name,
                         base_label if baseline else None,
                         None if station is None else (float(station[0]), float(station[1]), float(station[2])),
                         seen_label)


def plan_from_positions(c: Campaign, positions_layout) -> VisitPlan:
    """A visit's set-ups planned together from their planned positions (layout frame), before any coarse scan.

    With the campaign's scanner and planner settings (``min_points``, the visit's budget: ``visit_budget_min`` or
    ``budget_min`` a set-up, ``closure``, ``layout_up``): which set-up measures which target, the ties that join them, each one's share of the time
    (:func:`lidar.stations.plan_visit_from_positions`).
    """
    params = parameters(c)
    return plan_visit_from_positions(c.layout(), positions_layout, profile=c.profile,
                                     min_points=int(params["min_points"]),
                                     budget_seconds=visit_budget_seconds(params, len(positions_layout)),
                                     up=layout_up(params),
                                     closure=bool(params["closure"]),
                                     reference_factor=float(params["reference_points_factor"]))


def positions_visit_json(visit: VisitPlan, positions_layout) -> dict:
    """What :func:`plan_from_positions` planned, set-up by set-up.

    Targets, minutes, ties; no windows: the heading on site is not known yet.
    """
    rows = []
    for k in visit.order:
        plan = visit.plan(k)
        x, y, z = (round(float(v), 3) for v in positions_layout[k - 1])
        rows.append({"setup": k, "x": x, "y": y, "z": z, "minutes": round(plan.total_seconds / 60.0, 2),
                     "budget_share_minutes": round(plan.budget_seconds / 60.0, 2),
                     "targets": sorted({r.reflector for r in plan.rois if not r.closure}),
                     "deck_targets_assigned": sorted(t for t, j in visit.assignment.items() if j == k
                                                     and any(r.reflector == t and r.group == "measurement"
                                                             for r in plan.rois)),
                     "ties": list(visit.ties.get(k, ())), "second_sightings": list(visit.second.get(k, ())),
                     "points_per_target": plan.points_per_target, "skipped": [t for t, _ in plan.skipped],
                     "warnings": list(plan.warnings)})
    return {"planned_together": True, "total_minutes": round(visit.total_seconds / 60.0, 2),
            "budget_minutes": round(visit.budget_seconds / 60.0, 2), "setups": rows,
            "warnings": list(visit.warnings)}


def _field_model(c: Campaign, params: dict):
    """The campaign's stored field model, when processing uses one."""
    got = c.field_model() if params.get("field_model", True) else None
    return None if got is None else got[0]


def station_map_figure(advice: StationAdvice, layout, *, title: str = ""):
    """Map of the candidate stations coloured by their worst predicted sigma, over the layout."""
    matplotlib.use("Agg", force=False)

    fig = Figure(figsize=(9, 6.5), dpi=110)
    draw_station_map(fig.add_subplot(111), advice, layout, title=title)
    fig.tight_layout()
    return fig


def draw_station_map(ax, advice: StationAdvice, layout, *, title: str = "") -> None:
    """Draw the station map on a matplotlib Axes (the file export and the application share it)."""
    st = advice.stations
    xy = np.array([s.xyz_layout[:2] for s in st]).reshape(-1, 2)
    worst = np.array([s.worst_sigma_mm for s in st])
    full = np.array([s.usable and not s.hidden for s in st], dtype=bool)
    ok = np.isfinite(worst) & full
    if np.any(ok):
        lo = float(worst[ok].min())
        hi = max(float(np.percentile(worst[ok], 95)), lo + 1e-3)
        sc = ax.scatter(xy[ok, 0], xy[ok, 1], c=worst[ok], s=22, cmap="viridis_r", vmin=lo, vmax=hi, marker="s")
        ax.figure.colorbar(sc, ax=ax, label="worst target's predicted σ (mm)")
    if np.any(~ok):
        ax.scatter(xy[~ok, 0], xy[~ok, 1], s=10, c="0.75", marker="x", label="a target hidden")
    for k, tid in enumerate(layout.ids):
        x, y = layout.xyz[k, :2]
        ax.plot(x, y, "o" if layout.groups[k] == "measurement" else "^", color="tab:red", ms=6)
        ax.annotate(tid, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    poly = np.vstack([advice.area_xy, advice.area_xy[:1]])
    ax.plot(poly[:, 0], poly[:, 1], "k--", lw=0.8)
    if st and st[0].usable:
        b = st[0].xyz_layout
        ax.plot(b[0], b[1], marker="*", ms=16, color="gold", mec="k", ls="none",
                label=f"best: σ ≤ {st[0].worst_sigma_mm:.3f} mm")
    if advice.last_station is not None:
        ax.plot(advice.last_station[0], advice.last_station[1], marker="P", ms=11, color="tab:orange", mec="k",
                ls="none", label="last station")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, layout frame)")
    ax.set_ylabel("y (m, layout frame)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or f"Where to stand ({advice.scanner}, instrument {advice.height_m:g} m above ground)")

"""Simulated visits written as files, exactly as a surveyor would bring them back from the field.

A visit folder holds ``scene.json`` (the set-up, the bridge and its state: ground
truth input), ``coarse.laz``, ``truth.json`` and, after planning,
``fine.laz`` with the planned windows. Scan files are in the scanner frame and
carry no pose: processing must not depend on the simulator. Timed visits
(:class:`~lidar.simulate.effects.VisitTiming` or a drift) give every point
its time (LAS ``gps_time``).
"""
from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from common.errors import InputError
from lidar.io.las import write_las
from lidar.scan import Scan
from lidar.simulate.bridge import BridgeModel, model_from_dict, model_to_dict
from lidar.simulate.effects import (
    AxisErrors,
    DeckTransient,
    DriftModel,
    IntensityModel,
    VisitTiming,
    walk_from_dict,
    walk_to_dict,
)
from lidar.simulate.scene import BridgeScene, EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth, WindowTruth

if TYPE_CHECKING:
    from lidar.plan import RoiPlan

SCENE_FORMAT_VERSION = 2  # 2: the bridge model and the systematic effects (written only when not the defaults)


def conditions_to_dict(c: EpochConditions) -> dict:
    """The conditions as JSON values: today's keys always, each new effect only when it is on."""
    d: dict = {
        "midspan_displacement_m": c.midspan_displacement_m,
        "moved_targets": {k: list(v) for k, v in c.moved_targets.items()},
        "occluded": list(c.occluded), "cable_ties": list(c.cable_ties),
        "removed": list(c.removed), "saturated": c.saturated,
    }
    extra = {
        "span_displacements_m": list(c.span_displacements_m), "deck_strain": c.deck_strain,
        "fixed_bearing_x_m": c.fixed_bearing_x_m, "deck_strain_across": c.deck_strain_across,
        "range_scale_ppm": c.range_scale_ppm,
        "range_scale_rate_ppm_h": c.range_scale_rate_ppm_h,
        "range_walk": walk_to_dict(c.range_walk), "clipped_fraction": c.clipped_fraction,
        "drift": None if c.drift is None else c.drift.to_dict(),
        "timing": None if c.timing is None else c.timing.to_dict(),
        "axis_errors": None if c.axis_errors is None else c.axis_errors.to_dict(),
        "walk_factors": dict(c.walk_factors),
        "transient": None if c.transient is None else c.transient.to_dict(),
        "intensity_model": None if c.intensity_model is None else c.intensity_model.to_dict(),
        "pier_shifts": {str(k): list(v) for k, v in c.pier_shifts.items()},
    }
    d.update({k: v for k, v in extra.items() if v not in (None, 0.0, [], {})})
    return d


def conditions_from_dict(c: dict) -> EpochConditions:
    """The conditions written by :func:`conditions_to_dict`."""
    return EpochConditions(
        c["midspan_displacement_m"], c["moved_targets"], tuple(c["occluded"]), tuple(c["cable_ties"]),
        tuple(c["removed"]), bool(c["saturated"]), span_displacements_m=tuple(c.get("span_displacements_m", ())),
        deck_strain=float(c.get("deck_strain", 0.0)), fixed_bearing_x_m=c.get("fixed_bearing_x_m"),
        deck_strain_across=float(c.get("deck_strain_across", 0.0)),
        range_scale_ppm=float(c.get("range_scale_ppm", 0.0)),
        range_scale_rate_ppm_h=float(c.get("range_scale_rate_ppm_h", 0.0)), range_walk=walk_from_dict(c.get("range_walk")),
        clipped_fraction=float(c.get("clipped_fraction", 0.0)), drift=DriftModel.from_dict(c.get("drift")),
        timing=VisitTiming.from_dict(c.get("timing")), axis_errors=AxisErrors.from_dict(c.get("axis_errors")),
        walk_factors=dict(c.get("walk_factors") or {}), transient=DeckTransient.from_dict(c.get("transient")),
        intensity_model=IntensityModel.from_dict(c.get("intensity_model")),
        pier_shifts={int(k): tuple(v) for k, v in (c.get("pier_shifts") or {}).items()})


def save_scene(folder: Path, setup: ScannerSetup, conditions: EpochConditions, seed: int,
               coarse_step_deg: float, *, model: BridgeModel | None = None) -> Path:
    """Write ``scene.json``: what a visit folder's simulated scans were made from (to scan it again).

    The bridge model is written when it is not the default one; a scene of today's bridge without any of
    the new effects is written exactly as before (format 1).
    """
    cond = conditions_to_dict(conditions)
    spec: dict = {
        "format_version": 1,
        "setup": asdict(setup),
        "conditions": cond,
        "seed": int(seed),
        "coarse_step_deg": float(coarse_step_deg),
    }
    if model is not None and model != BridgeModel():
        spec["model"] = model_to_dict(model)
    if "model" in spec or set(cond) - _LEGACY_CONDITION_KEYS:
        spec["format_version"] = SCENE_FORMAT_VERSION
    p = folder / "scene.json"
    p.write_text(json.dumps(spec, indent=1))
    return p


_LEGACY_CONDITION_KEYS = {"midspan_displacement_m", "moved_targets", "occluded", "cable_ties", "removed", "saturated"}


def _scene_spec(folder: Path) -> dict:
    p = Path(folder) / "scene.json"
    if not p.is_file():
        raise InputError(f"{p}: no simulated scene here; run 'bridgesurvey simulate {folder}' first")
    d = json.loads(p.read_text())
    if int(d.get("format_version", 1)) > SCENE_FORMAT_VERSION:
        raise InputError(f"{p}: written by a newer BridgeSurvey")
    return d


def load_scene(folder: Path) -> tuple[ScannerSetup, EpochConditions, int, float]:
    """Read a visit folder's ``scene.json``: (set-up, conditions, seed, coarse step in degrees)."""
    d = _scene_spec(folder)
    setup = ScannerSetup(**{**d["setup"], "position_m": tuple(d["setup"]["position_m"])})
    return setup, conditions_from_dict(d["conditions"]), int(d["seed"]), float(d["coarse_step_deg"])


def load_scene_model(folder: Path) -> BridgeModel:
    """The bridge model of a visit folder's ``scene.json`` (the default bridge when it names none)."""
    d = _scene_spec(folder)
    return model_from_dict(d["model"]) if "model" in d else BridgeModel()


def scan_order(rois: Sequence[RoiPlan]) -> list[RoiPlan]:
    """The order a visit scans its windows in: the plan's, closure windows last."""
    return [r for r in rois if not getattr(r, "closure", False)] + [r for r in rois if getattr(r, "closure", False)]


def simulate_coarse(folder: str | os.PathLike, *, setup: ScannerSetup, conditions: EpochConditions,
                    model: BridgeModel | None = None, seed: int = 0, coarse_step_deg: float = 0.04,
                    name: str = "coarse.laz") -> tuple[Path, ScanTruth]:
    """Write a coarse whole-bridge scan of one visit, its scene spec and its ground truth.

    Timed conditions (a timing or a drift): the coarse scan is the visit's first, from the timing's start.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model = model or BridgeModel()
    scene = BridgeScene(model, conditions, setup)
    scan, truth = scene.scan(scene.coarse_window(step_deg=coarse_step_deg), rng=np.random.default_rng(seed),
                             name="coarse")
    save_scene(folder, setup, conditions, seed, coarse_step_deg, model=model)
    truth.save(folder / "truth.json")
    return write_las(scan, folder / name), truth


def simulate_fine(folder: str | os.PathLike, rois: Sequence[RoiPlan], *, model: BridgeModel | None = None,
                  name: str = "fine.laz", truth_name: str = "truth_fine.json") -> tuple[Path, ScanTruth]:
    """Scan the planned windows of the visit in ``folder`` (same set-up and state as its coarse scan).

    Parameters
    ----------
    folder : path-like
        A visit folder written by :func:`simulate_coarse`.
    rois : sequence of RoiPlan
        The windows, scanned in :func:`scan_order` (closure windows last) into one file.
    model : BridgeModel, keyword-only
        Default: the one ``scene.json`` names (today's bridge when it names none).
    name, truth_name : str, keyword-only
        File names of the scan and of its truth in ``folder``. Defaults ``fine.laz`` and ``truth_fine.json``.

    Returns
    -------
    The scan's path and the visit's truth: every target as its window saw it and, when timed, the time span of
    the coarse scan and of every window (the coarse scan first, each window ``gap_s`` after the previous one).
    """
    folder = Path(folder)
    setup, conditions, seed, step = load_scene(folder)
    scene = BridgeScene(model or load_scene_model(folder), conditions, setup)
    rng = np.random.default_rng(seed + 1_000_003)
    scans, counts = [], {}
    times: dict[str, float] = {}
    windows: list[WindowTruth] = []
    clock = None
    if conditions.timed:
        t0 = conditions.visit_timing.start_s
        windows.append(WindowTruth("coarse", t0, t0 + scene.scan_seconds(scene.coarse_window(step_deg=step))))
        clock = windows[-1].end_s + conditions.visit_timing.gap_s
    ids = {d.target.id for d in scene.discs}
    for roi in scan_order(rois):
        s, truth = scene.scan(roi.window, rng=rng, name=roi.reflector, start_s=clock)
        scans.append(s)
        if roi.reflector not in counts:  # a closure window re-scans a target: its first window's figures stay
            counts[roi.reflector] = truth.target(roi.reflector).points_on_target if roi.reflector in ids else 0
            when = truth.target(roi.reflector).time_s if roi.reflector in ids else None
            if when is not None:
                times[roi.reflector] = when
        if clock is not None:
            windows.append(replace(truth.windows[0], closure=bool(getattr(roi, "closure", False))))
            clock = windows[-1].end_s + conditions.visit_timing.gap_s
    fine = Scan.concatenate(scans, name="fine")
    truth = scene.truth(counts, times_s=times if clock is not None else None, windows=tuple(windows))
    truth.save(folder / truth_name)
    return write_las(fine, folder / name), truth

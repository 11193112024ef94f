"""Simulated visits written as files, exactly as a surveyor would bring them back from the field.

A visit folder holds ``scene.json`` (the set-up and the bridge state: ground
truth input), ``coarse.laz``, ``truth.json`` and, after planning,
``fine.laz`` with the planned windows. Scan files are in the scanner frame and
carry no pose: processing must not depend on the simulator.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict
from pathlib import Path
from typing import Optional, Sequence, TYPE_CHECKING

import numpy as np

from common.errors import InputError
from lidar.io.las import write_las
from lidar.scan import Scan
from lidar.simulate.bridge import BridgeModel
from lidar.simulate.scene import BridgeScene, EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth

if TYPE_CHECKING:
    from lidar.plan import RoiPlan

SCENE_FORMAT_VERSION = 1


def save_scene(folder: Path, setup: ScannerSetup, conditions: EpochConditions, seed: int,
               coarse_step_deg: float) -> Path:
    """Write ``scene.json``: what a visit folder's simulated scans were made from (to scan it again)."""
    spec = {
        "format_version": SCENE_FORMAT_VERSION,
        "setup": asdict(setup),
        "conditions": {
            "midspan_displacement_m": conditions.midspan_displacement_m,
            "moved_targets": {k: list(v) for k, v in conditions.moved_targets.items()},
            "occluded": list(conditions.occluded), "cable_ties": list(conditions.cable_ties),
            "removed": list(conditions.removed), "saturated": conditions.saturated,
        },
        "seed": int(seed),
        "coarse_step_deg": float(coarse_step_deg),
    }
    p = folder / "scene.json"
    p.write_text(json.dumps(spec, indent=1))
    return p


def load_scene(folder: Path) -> tuple[ScannerSetup, EpochConditions, int, float]:
    """Read a visit folder's ``scene.json``: (set-up, conditions, seed, coarse step in degrees)."""
    p = Path(folder) / "scene.json"
    if not p.is_file():
        raise InputError(f"{p}: no simulated scene here; run 'bridgesurvey simulate {folder}' first")
    d = json.loads(p.read_text())
    if int(d.get("format_version", 1)) > SCENE_FORMAT_VERSION:
        raise InputError(f"{p}: written by a newer BridgeSurvey")
    setup = ScannerSetup(**{**d["setup"], "position_m": tuple(d["setup"]["position_m"])})
    c = d["conditions"]
    cond = EpochConditions(c["midspan_displacement_m"], c["moved_targets"], tuple(c["occluded"]),
                           tuple(c["cable_ties"]), tuple(c["removed"]), bool(c["saturated"]))
    return setup, cond, int(d["seed"]), float(d["coarse_step_deg"])


def simulate_coarse(folder: str | os.PathLike, *, setup: ScannerSetup, conditions: EpochConditions,
                    model: Optional[BridgeModel] = None, seed: int = 0, coarse_step_deg: float = 0.04,
                    name: str = "coarse.laz") -> tuple[Path, ScanTruth]:
    """Write a coarse whole-bridge scan of one visit, its scene spec and its ground truth."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    model = model or BridgeModel()
    scene = BridgeScene(model, conditions, setup)
    scan, truth = scene.scan(scene.coarse_window(step_deg=coarse_step_deg), rng=np.random.default_rng(seed),
                             name="coarse")
    save_scene(folder, setup, conditions, seed, coarse_step_deg)
    truth.save(folder / "truth.json")
    return write_las(scan, folder / name), truth


def simulate_fine(folder: str | os.PathLike, rois: Sequence[RoiPlan], *, model: Optional[BridgeModel] = None,
                  name: str = "fine.laz") -> tuple[Path, ScanTruth]:
    """Scan the planned windows of the visit in ``folder`` (same set-up and state as its coarse scan)."""
    folder = Path(folder)
    setup, conditions, seed, _ = load_scene(folder)
    scene = BridgeScene(model or BridgeModel(), conditions, setup)
    rng = np.random.default_rng(seed + 1_000_003)
    scans, counts = [], {}
    truth = None
    for roi in rois:
        s, truth = scene.scan(roi.window, rng=rng, name=roi.reflector)
        scans.append(s)
        counts[roi.reflector] = truth.target(roi.reflector).points_on_target if roi.reflector in \
            {t.id for t in truth.targets} else 0
    fine = Scan.concatenate(scans, name="fine")
    truth = scene.truth(counts)
    truth.save(folder / "truth_fine.json")
    return write_las(fine, folder / name), truth

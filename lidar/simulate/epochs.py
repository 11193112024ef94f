"""Simulated epochs with windows planned from the truth (no coarse scan, for speed).

The tests' and the accuracy benchmark's fixtures, and the 40 m bridge's version of the dissertation's
lab design (3 scanner positions x 4 loads).
"""
from __future__ import annotations

import numpy as np

from lidar.centroid import centroids_from_scan
from lidar.plan import PlanTarget, ScanPlan, plan_fine_scans
from lidar.scan import Scan
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.truth import ScanTruth

MODEL = BridgeModel()
GROUPS = {t.id: t.group for t in MODEL.targets}


def plan_from_truth(scene: BridgeScene, *, min_points: int = 1000, position_noise_m: float = 0.01,
                    rng: np.random.Generator | None = None) -> ScanPlan:
    """A fine-scan plan from the scene's true target positions, each disturbed by ``position_noise_m``."""
    rng = rng or np.random.default_rng(0)
    truth = scene.truth()
    targets = []
    for t in truth.targets:
        c = np.asarray(t.centre_socs_m)
        cos_inc = abs(np.asarray(t.normal_socs) @ (c / np.linalg.norm(c)))
        targets.append(PlanTarget(t.id, t.group, tuple(c + rng.normal(0, position_noise_m, 3)), 0.05, False, cos_inc))
    return plan_fine_scans(targets, min_points=min_points)


def fine_epoch(conditions: EpochConditions, setup: ScannerSetup, *, seed: int, min_points: int = 1000,
               range_noise_m: float | None = None) -> tuple[dict, ScanTruth, ScanPlan, Scan]:
    """Centroids (found only) and truth of one epoch scanned at its planned windows."""
    scene = BridgeScene(MODEL, conditions, setup)
    rng = np.random.default_rng(seed)
    plan = plan_from_truth(scene, min_points=min_points, rng=rng)
    scans, counts = [], {}
    for r in plan.rois:
        s, t = scene.scan(r.window, rng=rng, range_noise_m=range_noise_m)
        scans.append(s)
        counts[r.reflector] = t.target(r.reflector).points_on_target
    fine = Scan.concatenate(scans)
    cents = centroids_from_scan(fine.xyz_socs, np.asarray(fine.intensity), plan.rois)
    return {k: c for k, c in cents.items() if c.found}, scene.truth(counts), plan, fine


LAB_POSITIONS = (
    ScannerSetup((12.0, -11.0, 1.5), heading_deg=25.0, pitch_deg=0.03, roll_deg=-0.02),
    ScannerSetup((20.0, -14.0, 1.4), heading_deg=140.0, pitch_deg=-0.04, roll_deg=0.01),
    ScannerSetup((29.0, -12.0, 1.7), heading_deg=260.0, pitch_deg=0.02, roll_deg=0.05),
)
LAB_LOADS_MM = (0.0, -3.0, -6.0, -9.0)

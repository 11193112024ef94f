"""The dissertation's VZ-1000 field figures (section 4.3.2) from a scanner profile's time model.

Shared by ``plan_predictions`` and ``fidelity``. The dissertation gives 3 min for 1000 points on a pier
target, 7 min for 25,000 points at midspan, under an hour for the visit, and more than 10 h for a
full-resolution scan; it does not give where the scanner stood, so ranges are assumed.
"""
from __future__ import annotations

import math

from lidar.plan import PlanTarget, plan_fine_scans

PIER_RANGES_M = (15.0, 20.0, 30.0)
MIDSPAN_RANGES_M = (8.0, 10.0, 12.0)


def window(profile, range_m: float, cos_incidence: float, zenith_deg: float, points: int) -> tuple[float, int]:
    """(minutes, points on the target) of one planned window."""
    z = math.radians(zenith_deg)
    t = PlanTarget("T", "reference", (range_m * math.sin(z), 0.0, range_m * math.cos(z)), 0.05, False, cos_incidence)
    plan = plan_fine_scans([t], profile=profile, min_points=points, budget_seconds=1e7)
    return plan.rois[0].expected_seconds / 60, plan.rois[0].expected_target_points


def time_figures(profile) -> dict:
    """Pier and midspan windows over the assumed ranges, a 10-target visit, and a full-resolution 360 deg scan."""
    pier = [window(profile, r, 0.8, 88.0, 1000) for r in PIER_RANGES_M]
    mid = [window(profile, r, 0.85, 35.0, 25000) for r in MIDSPAN_RANGES_M]
    visit = 4 * pier[1][0] + 6 * window(profile, 10.0, 0.85, 35.0, 1000)[0]
    full_h = profile.window_seconds(360.0, profile.min_phi_step_deg, profile.min_theta_step_deg) / 3600
    return {"pier_min": (min(p[0] for p in pier), max(p[0] for p in pier)),
            "mid_min": (min(m[0] for m in mid), max(m[0] for m in mid)),
            "mid_points": (min(m[1] for m in mid), max(m[1] for m in mid)),
            "visit_min": visit, "full_h": full_h}

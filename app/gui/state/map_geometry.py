"""Map cells <-> scanner angles for one reflectance-map preview (plain values, no Qt)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.errors import InputError
from lidar.plan import new_roi


@dataclass(frozen=True)
class CellRect:
    """A rectangle on the map in cell units: ``left``/``top`` of its corner, ``width``/``height``."""

    left: float
    top: float
    width: float
    height: float

    @property
    def right(self) -> float:
        return self.left + self.width

    @property
    def bottom(self) -> float:
        return self.top + self.height


def window_of_cells(rect: CellRect, theta0: float, phi0: float, step: float) -> dict:
    """The plan window (degrees, plan-contract keys) a map rectangle covers.

    >>> window_of_cells(CellRect(10, 20, 5, 2), 60.0, 350.0, 0.1)
    {'phi_min_deg': 351.0, 'phi_max_deg': 351.5, 'theta_min_deg': 62.0, 'theta_max_deg': 62.2}
    >>> window_of_cells(CellRect(95, 20, 10, 2), 60.0, 350.0, 0.1)  # across 0 deg: starts below 0
    {'phi_min_deg': -0.5, 'phi_max_deg': 0.5, 'theta_min_deg': 62.0, 'theta_max_deg': 62.2}
    """
    phi_min = float(np.mod(phi0 + rect.left * step, 360.0))
    width = rect.width * step
    if phi_min + width > 360.0:
        phi_min -= 360.0  # a window across 0 deg starts below 0 (the plan contract)
    t0 = theta0 + rect.top * step
    return {"phi_min_deg": round(phi_min, 6), "phi_max_deg": round(phi_min + width, 6),
            "theta_min_deg": round(max(t0, 0.0), 6), "theta_max_deg": round(min(t0 + rect.height * step, 180.0), 6)}


def window_from_cells(preview, plan, rect: CellRect, rid: str, reflector):
    """A new plan window for ``rid`` from a rectangle drawn on an epoch's map preview (its range from the
    map's cells, its steps for the plan's points on a target of that size)."""
    rmap = preview.reflectance_map
    r0, r1 = int(max(rect.top, 0)), int(min(rect.bottom + 1, rmap.shape[0]))
    c0, c1 = int(max(rect.left, 0)), int(min(rect.right + 1, rmap.shape[1]))
    ranges = rmap.range_m[r0:r1, c0:c1]
    if ranges.size == 0 or not np.isfinite(ranges).any():
        raise InputError("the drawn window holds no scanned cell; draw it over the target")
    w = window_of_cells(rect, rmap.theta0_deg, rmap.phi0_deg, rmap.step_deg)
    return new_roi(rid, reflector.group, range_m=float(np.nanmedian(ranges)), diameter_m=reflector.diameter_m,
                   n_points=plan.min_points, profile=plan.profile, **w)

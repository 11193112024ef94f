"""Displacement series written by an existing dual-camera installation (CSV or text).

They are read by the one series reader, :func:`common.series.read_series` (separators, decimal commas,
units, time zones, gaps and bad rows: see there), as the quantity :data:`DISPLACEMENT`: values in
millimetres, positive up.
"""
from __future__ import annotations

import os

from common.series import Quantity, Series, read_series

UNITS_MM = {"um": 1e-3, "µm": 1e-3, "micron": 1e-3, "mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "inch": 25.4}
VALUE_NAMES = ("displacement", "disp", "deflection", "vertical", "dy", "uy", "value", "y")
DISPLACEMENT = Quantity("displacement", VALUE_NAMES, {k: (v, 0.0) for k, v in UNITS_MM.items()}, "mm", "mm")


def read_camera_series(path: str | os.PathLike, *, column: str | None = None, timezone: str = "UTC",
                       unit: str | None = None, positive: str = "up", gap_factor: float = 3.0) -> Series:
    """Read a displacement series file (:func:`common.series.read_series` with :data:`DISPLACEMENT`).

    The series' ``values`` are millimetres, positive up (``unit`` ``mm``; ``unit_read`` the file's unit).

    Parameters
    ----------
    path : CSV or text file.
    column : name of the value column when more than one could be it.
    timezone : for times without an offset and no time-zone column (IANA name or ``+hh:mm``).
    unit : the values' unit when neither the column name nor a unit column tells (default mm).
    positive : ``up`` (default) or ``down`` -- the file's sign convention; stored values are positive up.
    gap_factor : a pause longer than this many median sampling intervals is reported as a gap.
    """
    return read_series(path, quantity=DISPLACEMENT, column=column, timezone=timezone, unit=unit, positive=positive,
                       gap_factor=gap_factor)

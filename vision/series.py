"""Displacement series written by an existing dual-camera installation (CSV or text).

They are read by the one series reader, :func:`common.series.read_series` (separators, decimal commas,
units, time zones, gaps and bad rows: see there), as the quantity :data:`DISPLACEMENT`: values in
millimetres, positive up.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from common.series import Quantity, Series, read_series, series_arrays_from_npz, series_npz_bytes

UNITS_MM = {"um": 1e-3, "µm": 1e-3, "micron": 1e-3, "mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "inch": 25.4}
VALUE_NAMES = ("displacement", "disp", "deflection", "vertical", "dy", "uy", "value", "y")
DISPLACEMENT = Quantity("displacement", VALUE_NAMES, {k: (v, 0.0) for k, v in UNITS_MM.items()}, "mm", "mm")


@dataclass(frozen=True)
class CameraSeries:
    """A displacement series in millimetres (positive up) at UTC times.

    Attributes
    ----------
    time_ns : (n,) int64 UTC nanoseconds, increasing.
    value_mm : (n,) float64; NaN marks a gap value (the row was there but empty).
    source : the file it came from; ``column`` the value column used; ``unit`` the unit read.
    bad_rows : rows left out, with line numbers, ``n_bad`` their count.
    gaps : (start_ns, end_ns) of pauses longer than ``gap_factor`` sampling intervals.
    sampling_s : median sampling interval in seconds.
    times_read : how the times were read, naming the zone assumed for times without an offset.
    """

    time_ns: np.ndarray
    value_mm: np.ndarray
    source: str = ""
    column: str = ""
    unit: str = "mm"
    bad_rows: tuple = ()
    n_bad: int = 0
    n_rows: int = 0
    n_missing: int = 0
    n_duplicates: int = 0
    gaps: tuple = ()
    sampling_s: float = float("nan")
    times_read: str = ""
    notes: tuple = field(default_factory=tuple)

    def __len__(self) -> int:
        return len(self.time_ns)

    def summary(self) -> dict:
        """What the import found (see :meth:`common.series.Series.summary`); ``unit`` is the unit read."""
        s = Series(self.time_ns, self.value_mm, "mm", unit_read=self.unit, column=self.column,
                   bad_rows=self.bad_rows, n_bad=self.n_bad, n_rows=self.n_rows, n_missing=self.n_missing,
                   n_duplicates=self.n_duplicates, gaps=self.gaps, sampling_s=self.sampling_s,
                   times_read=self.times_read, notes=self.notes).summary()
        s["unit"] = self.unit
        return s

    def to_npz_bytes(self) -> bytes:
        """The stored form of the arrays (:func:`common.series.series_npz_bytes`)."""
        return series_npz_bytes(self.time_ns, self.value_mm)

    @staticmethod
    def arrays_from_npz(data: bytes) -> tuple[np.ndarray, np.ndarray]:
        """``(time_ns, value_mm)`` of :meth:`to_npz_bytes`."""
        return series_arrays_from_npz(data)


def read_camera_series(path: str | os.PathLike, *, column: str | None = None, timezone: str = "UTC",
                       unit: str | None = None, positive: str = "up", gap_factor: float = 3.0) -> CameraSeries:
    """Read a displacement series file (:func:`common.series.read_series` with :data:`DISPLACEMENT`).

    Parameters
    ----------
    path : CSV or text file.
    column : name of the value column when more than one could be it.
    timezone : for times without an offset and no time-zone column (IANA name or ``+hh:mm``).
    unit : the values' unit when neither the column name nor a unit column tells (default mm).
    positive : ``up`` (default) or ``down`` -- the file's sign convention; stored values are positive up.
    gap_factor : a pause longer than this many median sampling intervals is reported as a gap.
    """
    s = read_series(path, quantity=DISPLACEMENT, column=column, timezone=timezone, unit=unit, positive=positive,
                    gap_factor=gap_factor)
    return CameraSeries(time_ns=s.time_ns, value_mm=s.values, source=s.source, column=s.column, unit=s.unit_read,
                        bad_rows=s.bad_rows, n_bad=s.n_bad, n_rows=s.n_rows, n_missing=s.n_missing,
                        n_duplicates=s.n_duplicates,
                        gaps=s.gaps, sampling_s=s.sampling_s, times_read=s.times_read, notes=s.notes)

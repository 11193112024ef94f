"""What explains a displacement history: environment series and events.

Environment series are air and structure temperature, sun, rain, snow and humidity; events are
construction steps, loads and repairs.

Series are read by the one series reader, :func:`common.series.read_series`, as camera series are
(separators, decimal commas, units, time zones, gaps and bad rows reported), and kept read-only in the
campaign's ``environment/`` folder.
"""
from __future__ import annotations

import datetime as dt
import os
from dataclasses import dataclass

import numpy as np

from common.errors import InputError
from common.series import Quantity, Series, read_series, series_arrays_from_npz, series_npz_bytes
from projects.store.campaign import ENV_DIR, Campaign, parse_datetime
from projects.store.records import EventRecord, SeriesRecord

_TEMP_UNITS = {"degc": (1.0, 0.0), "c": (1.0, 0.0), "°c": (1.0, 0.0), "celsius": (1.0, 0.0),
               "degf": (5 / 9, -160 / 9), "f": (5 / 9, -160 / 9), "°f": (5 / 9, -160 / 9),
               "fahrenheit": (5 / 9, -160 / 9), "k": (1.0, -273.15), "kelvin": (1.0, -273.15)}
KINDS: dict[str, Quantity] = {
    "temperature": Quantity("air temperature", ("temperature", "air_temperature", "temp", "t_air", "ta", "value"),
                            _TEMP_UNITS, "degc", "°C", signed=False),
    "structure-temperature": Quantity("structure temperature",
                                      ("structure_temperature", "concrete_temperature", "t_struct", "temperature",
                                       "temp", "value"), _TEMP_UNITS, "degc", "°C", signed=False),
    "solar": Quantity("solar radiation", ("solar", "radiation", "irradiance", "ghi", "value"),
                      {"w/m2": (1.0, 0.0), "w_m2": (1.0, 0.0), "wm2": (1.0, 0.0), "kw/m2": (1000.0, 0.0)},
                      "w/m2", "W/m²", signed=False),
    "rain": Quantity("rainfall", ("rain", "rainfall", "precipitation", "precip", "value"),
                     {"mm": (1.0, 0.0), "cm": (10.0, 0.0), "in": (25.4, 0.0)}, "mm", "mm", signed=False),
    "snow": Quantity("snow depth", ("snow", "snow_depth", "snowfall", "value"),
                     {"cm": (1.0, 0.0), "mm": (0.1, 0.0), "m": (100.0, 0.0)}, "cm", "cm", signed=False),
    "pressure": Quantity("air pressure", ("pressure", "air_pressure", "p", "qfe", "baro", "value"),
                         {"hpa": (1.0, 0.0), "mbar": (1.0, 0.0), "pa": (0.01, 0.0), "kpa": (10.0, 0.0),
                          "mmhg": (1.33322, 0.0), "inhg": (33.8639, 0.0)}, "hpa", "hPa", signed=False),
    "humidity": Quantity("relative humidity", ("humidity", "relative_humidity", "rh", "value"),
                         {"%": (1.0, 0.0), "pct": (1.0, 0.0), "percent": (1.0, 0.0), "fraction": (100.0, 0.0)},
                         "%", "%", signed=False),
}
EVENT_KINDS = ("construction", "load", "repair", "other")


@dataclass(frozen=True)
class EnvSeries:
    """A stored environment series: values in its kind's unit at UTC times (NaN: a gap value)."""

    name: str
    kind: str
    unit: str
    time_ns: np.ndarray
    value: np.ndarray


def import_env(c: Campaign, path: str | os.PathLike, *, kind: str, name: str | None = None,
               column: str | None = None, unit: str | None = None, timezone: str | None = None
               ) -> tuple[str, Series]:
    """Read an environment series file, copy it into the campaign (read-only) and store it.

    ``timezone`` is the zone of times without an offset (default: the campaign's, :attr:`Campaign.timezone`);
    the series' ``times_read`` says which was assumed. Bad rows are left out and counted. Nothing changes unless
    the file was read; the same file twice or a name in use is refused.
    """
    if kind not in KINDS:
        raise InputError(f"unknown series kind {kind!r}; use one of {', '.join(KINDS)}")
    zone = timezone or c.timezone
    path, name = c.series.check_new("env_series", path, name, "an environment series")
    sha = c.series.checksum_if_new("env_series", path)
    q = KINDS[kind]
    series = read_series(path, quantity=q, column=column, timezone=zone, unit=unit)
    if not np.any(np.isfinite(series.values)):
        raise InputError(f"{path}: every {q.noun} value is missing")
    options = {"column": series.column, "unit_read": series.unit_read, "unit": q.stored_unit, "timezone": zone}
    summary = series.summary()

    def record(conn, rel):
        c.series.insert(conn, "env_series", name=name, kind=kind, sha256=sha, stored_path=rel,
                        original_path=str(path.resolve()), options=options, summary=summary,
                        arrays=series_npz_bytes(series.time_ns, series.values))
        c.log_action(conn, "env-import", None, {"name": name, "kind": kind, "file": str(path), "sha256": sha,
                                           "rows": len(series), "bad_rows": series.n_bad, "timezone": zone})

    c.import_file(path, sha, ENV_DIR, record, journal_entry={  # what 'repair' needs to read it again
        "kind": "environment", "name": name, "series_kind": kind,
        "read": {"column": column, "unit": unit, "timezone": zone}})
    return name, series


def env_records(c: Campaign) -> list[SeriesRecord]:
    """The imported environment series (without their arrays), by kind and name."""
    return sorted(c.series.records("env_series"), key=lambda r: (r.kind, r.name))


def load_env(c: Campaign, *, kind: str | None = None, name: str | None = None) -> list[EnvSeries]:
    """Stored series of a kind (or the one named), oldest import first."""
    out = []
    for r in c.series.records("env_series", kind=kind, name=name):
        t, v = series_arrays_from_npz(c.series.arrays("env_series", r.name))
        out.append(EnvSeries(r.name, r.kind, r.options["unit"], t, v))
    if name is not None and not out:
        raise InputError(f"no environment series {name!r} in the campaign")
    return out


# ------------------------------------------------------------------------------------------- events
def add_event(c: Campaign, *, date: str, kind: str, label: str, load_kn_m: float | None = None) -> int:
    """Record a construction step, load, repair...

    The date must fall within the campaign's epochs (or up to a
    year after the last one, for an event whose effect is still to be measured).
    """
    if kind not in EVENT_KINDS:
        raise InputError(f"unknown event kind {kind!r}; use one of {', '.join(EVENT_KINDS)}")
    if not label.strip():
        raise InputError("an event needs a --label")
    if load_kn_m is not None and not (np.isfinite(load_kn_m) and load_kn_m >= 0):
        raise InputError(f"--load-kn-m must be a non-negative number, got {load_kn_m}")
    when = parse_datetime(date)
    epochs = c.epochs()
    if not epochs:
        raise InputError("the campaign has no epoch yet; add the visits before the events between them")
    first, last = epochs[0].datetime, epochs[-1].datetime

    limit = (dt.datetime.fromisoformat(last) + dt.timedelta(days=366)).isoformat()
    if when < first or when > limit:
        raise InputError(f"event date {when[:10]} is outside the campaign ({first[:10]} to {last[:10]}); its effect "
                         "cannot be measured from these epochs")
    return c.events.add(when, kind, label.strip(), load_kn_m)


def events(c: Campaign) -> list[EventRecord]:
    """The campaign's events, by date."""
    return c.events.all()

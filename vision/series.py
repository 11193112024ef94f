"""Import displacement series written by an existing dual-camera installation (CSV or text).

What is understood
------------------
* Separators: comma, semicolon, tab or runs of spaces (sniffed from the first data lines).
  Lines starting with ``#`` and blank lines are skipped.
* A header row naming the columns (case-insensitive):
  - time: ``timestamp``, ``datetime``, ``time``, ``date`` (or separate ``date`` and ``time``
    columns), ISO 8601 or ``YYYY-MM-DD hh:mm[:ss]``, or Unix seconds (``unix``, ``epoch_s``);
  - value: ``displacement``, ``disp``, ``deflection``, ``value``, ``dy``, ``vertical``... with an
    optional unit in the name (``displacement_mm``, ``disp [cm]``); or choose it by name;
  - optional ``unit`` column (per row: um, mm, cm, m, in) and ``tz``/``timezone``/``utc_offset``
    column (``+09:00``, ``UTC``, ``Asia/Seoul``).
* Empty cells, ``NaN``, ``NA``, ``null`` and ``-`` are gaps (kept as missing values).
* Rows whose time or value cannot be read, or with the wrong number of fields, are *bad rows*:
  left out and reported with their line numbers.

Times are stored as UTC (int64 nanoseconds); naive times take the ``timezone`` argument.
"""
from __future__ import annotations

import datetime as dt
import io
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.errors import InputError, SurveyError

SERIES_FORMAT_VERSION = 1
NAN_TOKENS = {"", "nan", "na", "n/a", "null", "none", "-", "--"}
UNITS_MM = {"um": 1e-3, "µm": 1e-3, "micron": 1e-3, "mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "inch": 25.4}
TIME_NAMES = ("timestamp", "datetime", "date_time", "time_utc", "time", "date")
UNIX_NAMES = ("unix", "unix_s", "epoch_s", "posix", "unixtime")
VALUE_NAMES = ("displacement", "disp", "deflection", "vertical", "dy", "uy", "value", "y")
UNIT_NAMES = ("unit", "units")
TZ_NAMES = ("tz", "timezone", "time_zone", "utc_offset", "offset")
MAX_BAD_LISTED = 1000  # bad rows kept with their line numbers (all are counted)


@dataclass(frozen=True)
class Quantity:
    """What a series file's value column holds, for the reader.

    Column names to look for, units as
    ``name -> (scale, offset)`` into the stored unit (``stored = value * scale + offset``), the default
    unit, and a noun for messages.
    """

    noun: str
    value_names: tuple[str, ...]
    units: dict
    default_unit: str
    stored_unit: str
    signed: bool = True  # whether ``positive='down'`` may flip it


DISPLACEMENT = Quantity("displacement", VALUE_NAMES, {k: (v, 0.0) for k, v in UNITS_MM.items()}, "mm", "mm")


class SeriesFormatError(SurveyError):
    """A camera series file cannot be read."""

    def __init__(self, path, problem: str):
        super().__init__(f"{path}: {problem}")


@dataclass(frozen=True)
class BadRow:
    """A row of a series file that could not be read: its line number and why."""

    line: int
    reason: str


@dataclass(frozen=True)
class CameraSeries:
    """A displacement series in millimetres (positive up) at UTC times.

    Attributes
    ----------
    time_ns : (n,) int64 UTC nanoseconds, increasing.
    value_mm : (n,) float64; NaN marks a gap value (the row was there but empty).
    source : the file it came from; ``column`` the value column used; ``unit`` the unit read.
    bad_rows : rows left out, with line numbers (the first ``MAX_BAD_LISTED``), ``n_bad`` their count.
    gaps : (start_ns, end_ns) of pauses longer than ``gap_factor`` sampling intervals.
    sampling_s : median sampling interval in seconds.
    """

    time_ns: np.ndarray
    value_mm: np.ndarray
    source: str = ""
    column: str = ""
    unit: str = "mm"
    bad_rows: tuple = ()
    n_bad: int = 0
    n_missing: int = 0
    n_duplicates: int = 0
    gaps: tuple = ()
    sampling_s: float = float("nan")
    notes: tuple = field(default_factory=tuple)

    def __len__(self) -> int:
        return len(self.time_ns)

    def summary(self) -> dict:

        def iso(ns):
            return dt.datetime.fromtimestamp(int(ns) / 1e9, dt.UTC).isoformat()

        return {"rows": len(self), "start": iso(self.time_ns[0]) if len(self) else None,
                "end": iso(self.time_ns[-1]) if len(self) else None, "sampling_s": self.sampling_s,
                "missing_values": self.n_missing, "bad_rows": self.n_bad, "duplicates_dropped": self.n_duplicates,
                "gaps": len(self.gaps), "column": self.column, "unit": self.unit,
                "first_bad_lines": [f"line {b.line}: {b.reason}" for b in self.bad_rows[:10]],
                "notes": list(self.notes)}

    def to_npz_bytes(self) -> bytes:
        buf = io.BytesIO()
        np.savez_compressed(buf, version=np.int64(SERIES_FORMAT_VERSION), time_ns=self.time_ns,
                            value_mm=self.value_mm)
        return buf.getvalue()

    @staticmethod
    def arrays_from_npz(data: bytes) -> tuple[np.ndarray, np.ndarray]:
        with np.load(io.BytesIO(data)) as z:
            version = int(z["version"])
            if version > SERIES_FORMAT_VERSION:
                raise InputError(f"camera series stored by a newer BridgeSurvey (format {version}); update it")
            return z["time_ns"].astype(np.int64), z["value_mm"].astype(np.float64)


def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9µ]+", "_", name.strip().lower()).strip("_")


def _unit_in_name(name: str, units=UNITS_MM) -> str | None:
    alt = "|".join(sorted((re.escape(u) for u in units), key=len, reverse=True))
    m = re.search(rf"(?:[_\[\(\s]|^)({alt})(?:[\]\)\s]|$)", name.strip().lower())
    if m is None:
        m = re.search(rf"_({alt})$", _norm(name))
    return m.group(1) if m else None


def _find(names: list[str], wanted) -> int | None:
    normed = [_norm(n) for n in names]
    for w in wanted:
        for i, n in enumerate(normed):
            if n == w or n.startswith(w + "_"):
                return i
    return None


def _sniff_separator(lines: list[str]) -> str | None:
    sample = lines[:20]
    for sep in (",", ";", "\t"):
        counts = {ln.count(sep) for ln in sample}
        if len(counts) == 1 and counts.pop() > 0:
            return sep
    return None  # whitespace


def read_camera_series(path: str | os.PathLike, *, column: str | None = None, timezone: str = "UTC",
                       unit: str | None = None, positive: str = "up", gap_factor: float = 3.0,
                       max_bad_fraction: float = 0.05, quantity: Quantity = DISPLACEMENT) -> CameraSeries:
    """Read a displacement series file (see the module documentation for what is understood).

    ``quantity`` makes the same reader take other series (temperature, radiation...): its value
    column names and units; ``value_mm`` then holds the values in ``quantity.stored_unit``.

    It runs in stages: the options are checked, the text is split into a table
    (:func:`_read_table`), the time and value columns are found (:func:`_find_columns`), the times
    (:func:`_read_times`) and values (:func:`_read_values`) are parsed with every bad row listed, and
    the series is put in time order with its gaps and repeats noted (:func:`_assemble`).

    Parameters
    ----------
    path : CSV or text file.
    column : name of the value column when more than one could be it.
    timezone : for times without an offset and no time-zone column (IANA name or ``+hh:mm``).
    unit : the values' unit when neither the column name nor a unit column tells (default mm).
    positive : ``up`` (default) or ``down`` -- the file's sign convention; stored values are positive up.
    gap_factor : a pause longer than this many median sampling intervals is reported as a gap.
    max_bad_fraction : refuse the file when more rows than this fraction are bad.
    """
    path = Path(path)
    _check_options(path, timezone, positive)
    tab = _read_table(path)
    cols = _find_columns(path, tab.header, column)
    t_ns, t_ok = _read_times(tab, cols, timezone)
    vals, missing, scale, offset, v_ok, file_unit = _read_values(tab, cols, t_ok, unit, quantity)
    good = t_ok & v_ok
    if good.sum() == 0:
        first = min(tab.bad, key=lambda b: b.line) if tab.bad else None
        raise SeriesFormatError(path, f"no readable rows ({tab.n_bad} bad; first: "
                                f"{first.reason if first else 'none'} at line {first.line if first else '?'})")
    if tab.n_bad > max_bad_fraction * tab.n_rows:
        first = "; ".join(f"line {b.line}: {b.reason}" for b in sorted(tab.bad, key=lambda b: b.line)[:3])
        raise SeriesFormatError(path, f"{tab.n_bad} of {tab.n_rows} rows are bad (more than "
                                f"{max_bad_fraction:.0%}); {first}")
    sign = 1.0 if positive == "up" or not quantity.signed else -1.0
    v = np.where(missing[good], np.nan, (vals[good] * scale[good] + offset[good]) * sign)
    return _assemble(path, tab, t_ns[good], v, tab.header[cols.value], file_unit, gap_factor)


@dataclass
class _Table:
    """A series file split into fields: every row that has the header's field count, as text."""

    header: list[str]
    df: Any                # pandas DataFrame of str, columns 0..n-1 (pandas has no type stubs here)
    line_no: np.ndarray    # file line of each row (1-based)
    sep: str | None
    n_rows: int            # data rows in the file, bad ones included
    bad: list              # BadRow, the first MAX_BAD_LISTED
    n_bad: int


@dataclass(frozen=True)
class _Columns:
    unix: int | None
    time: int | None
    date: int | None
    clock: int | None
    unit: int | None
    zone: int | None
    value: int


def _check_options(path: Path, timezone: str, positive: str) -> None:
    import pandas as pd

    try:
        pd.Timestamp("2026-01-01").tz_localize(_zone(timezone))
    except Exception:  # pytz/zoneinfo raise several types for unknown zones
        raise InputError(f"time zone {timezone!r} is not known; use an IANA name such as Europe/Berlin or an "
                         "offset such as +09:00") from None
    if positive not in ("up", "down"):
        raise InputError(f"positive must be 'up' or 'down', not {positive!r}")
    if not path.is_file():
        raise InputError(f"{path}: no such file; check the path")


def _read_table(path: Path) -> _Table:
    """The header and the rows of a series file; rows with the wrong field count are listed as bad."""
    import pandas as pd

    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise SeriesFormatError(path, "not a text file (CSV or TXT expected)") from None
    all_lines = text.splitlines()
    keep = [i for i, ln in enumerate(all_lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not keep:
        raise SeriesFormatError(path, "no data rows")
    lines = [all_lines[i] for i in keep]
    sep = _sniff_separator(lines[1:] or lines)
    split = (lambda s: s.split(sep)) if sep else (lambda s: s.split())
    header = [h.strip().strip('"') for h in split(lines[0])]
    if all(_is_number(h) for h in header):
        raise SeriesFormatError(path, "no header row; the first line must name the columns (e.g. time,displacement_mm)")
    ncol = len(header)
    body, body_lines = lines[1:], keep[1:]
    if not body:
        raise SeriesFormatError(path, "a header but no data rows")
    bad: list[BadRow] = []
    if sep:
        counts = np.fromiter((ln.count(sep) for ln in body), dtype=np.int64, count=len(body))
        ok_fields = counts == ncol - 1
    else:
        ok_fields = np.fromiter((len(ln.split()) == ncol for ln in body), dtype=bool, count=len(body))
    n_bad = _add_bad(bad, ~ok_fields, np.asarray(body_lines) + 1, lambda j: f"expected {ncol} fields")
    good_idx = np.nonzero(ok_fields)[0]
    data = "\n".join(body[j] for j in good_idx)
    try:
        df = pd.read_csv(io.StringIO(data), sep=sep if sep else r"\s+", header=None, names=list(range(ncol)),
                         dtype=str, keep_default_na=False, engine="c" if sep else "python", quotechar='"')
    except Exception as exc:  # pandas' parser errors have many types
        raise SeriesFormatError(path, f"cannot be parsed as a table ({str(exc).splitlines()[0]})") from None
    line_no = np.asarray(body_lines, dtype=np.int64)[good_idx] + 1
    return _Table(header, df, line_no, sep, len(body), bad, n_bad)


def _find_columns(path: Path, header: list[str], column: str | None) -> _Columns:
    """Which column holds the time, the unit, the time zone and the value.

    The time is unix seconds, a date-time, or a date and a clock; the time zone and the value (``column`` when given, else by name, else the one column left).
    """
    t_unix = _find(header, UNIX_NAMES)
    t_col = _find(header, TIME_NAMES)
    date_col, clock_col = _find(header, ("date",)), _find(header, ("time", "clock"))
    unit_col = _find(header, UNIT_NAMES)
    tz_col = _find(header, TZ_NAMES)
    used = {i for i in (t_unix, t_col, date_col, clock_col, unit_col, tz_col) if i is not None}
    if t_unix is None and t_col is None:
        raise SeriesFormatError(path, f"no time column (one of {', '.join(TIME_NAMES + UNIX_NAMES)}); "
                                f"the columns are {', '.join(header)}")
    if column is not None:
        matches = [i for i, h in enumerate(header) if h == column or _norm(h) == _norm(column)]
        if not matches:
            raise InputError(f"{path}: no column {column!r}; the columns are {', '.join(header)}")
        v_col = matches[0]
    else:
        found = _find([h if i not in used else "" for i, h in enumerate(header)], VALUE_NAMES)
        if found is None:
            candidates = [i for i in range(len(header)) if i not in used]
            if len(candidates) != 1:
                raise InputError(f"{path}: cannot tell which column holds the displacement "
                                 f"({', '.join(header)}); name it with --column")
            found = candidates[0]
        v_col = found
    return _Columns(t_unix, t_col, date_col, clock_col, unit_col, tz_col, v_col)


def _read_times(tab: _Table, cols: _Columns, timezone: str) -> tuple[np.ndarray, np.ndarray]:
    """(UTC nanoseconds, readable mask) of every row; unreadable times are listed as bad rows."""
    import pandas as pd

    df = tab.df
    if cols.unix is not None:
        secs = pd.to_numeric(df[cols.unix].str.strip(), errors="coerce").to_numpy(float)
        t_ok = np.isfinite(secs)
        t_ns = np.where(t_ok, np.round(np.nan_to_num(secs) * 1e9), 0).astype(np.int64)
    else:
        raw = df[cols.time].str.strip()
        if cols.date is not None and cols.clock is not None and cols.date != cols.clock:
            raw = df[cols.date].str.strip() + " " + df[cols.clock].str.strip()
        if cols.zone is not None:
            t_ns, t_ok = _times_with_zone_column(raw, df[cols.zone].str.strip())
        else:
            t_ns, t_ok = _parse_times(raw, timezone)
    t_of = cols.unix if cols.unix is not None else cols.time
    tab.n_bad += _add_bad(tab.bad, ~t_ok, tab.line_no, lambda j: f"time {df.iat[j, t_of]!r} is not a date-time")
    return t_ns, t_ok


def _read_values(tab: _Table, cols: _Columns, t_ok: np.ndarray, unit: str | None, quantity: Quantity):
    """(values, missing mask, scale and offset to the stored unit per row, readable mask, unit text).

    Values and units that cannot be read are listed as bad rows.
    """
    import pandas as pd

    df = tab.df
    vraw = df[cols.value].str.strip()
    missing = vraw.str.lower().isin(NAN_TOKENS).to_numpy()
    vals = pd.to_numeric(vraw.str.replace(",", ".", regex=False) if tab.sep != "," else vraw,
                         errors="coerce").to_numpy(float)
    v_bad = ~missing & ~np.isfinite(vals) & t_ok
    table = quantity.units
    file_unit = unit or _unit_in_name(tab.header[cols.value], table) or quantity.default_unit
    if file_unit.lower() not in table:
        raise InputError(f"unknown unit {file_unit!r} for a {quantity.noun}; use one of {', '.join(table)}")
    scale = np.full(len(df), table[file_unit.lower()][0])
    offset = np.full(len(df), table[file_unit.lower()][1])
    u_bad = np.zeros(len(df), bool)
    if cols.unit is not None:
        units = df[cols.unit].str.strip().str.lower()
        mapped = units.map({k: v[0] for k, v in table.items()}).to_numpy(float)
        mapped_off = units.map({k: v[1] for k, v in table.items()}).to_numpy(float)
        u_bad = ~np.isfinite(mapped) & t_ok & ~v_bad
        scale = np.where(np.isfinite(mapped), mapped, scale)
        offset = np.where(np.isfinite(mapped_off), mapped_off, offset)
        file_unit = "per row (" + ", ".join(sorted(set(units[~u_bad].unique()) & set(table))) + ")"
    tab.n_bad += _add_bad(tab.bad, v_bad, tab.line_no, lambda j: f"value {df.iat[j, cols.value]!r} is not a number")
    tab.n_bad += _add_bad(tab.bad, u_bad, tab.line_no, lambda j: f"unit {df.iat[j, cols.unit]!r} is not known")
    return vals, missing, scale, offset, ~v_bad & ~u_bad, file_unit


def _assemble(path: Path, tab: _Table, t: np.ndarray, v: np.ndarray, column: str, unit: str,
              gap_factor: float) -> CameraSeries:
    """The series in time order, a repeated time stamp kept once, with its sampling and gaps."""
    in_order = bool(np.all(np.diff(t) >= 0))
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    dup = np.concatenate([[False], np.diff(t) == 0])
    n_dup = int(dup.sum())
    t, v = t[~dup], v[~dup]
    dt_s = np.diff(t) / 1e9
    sampling = float(np.median(dt_s)) if len(dt_s) else float("nan")
    gaps: tuple[tuple[int, int], ...] = ()
    if len(dt_s) and sampling > 0:
        idx = np.nonzero(dt_s > gap_factor * sampling)[0]
        gaps = tuple((int(t[i]), int(t[i + 1])) for i in idx)
    notes = []
    if n_dup:
        notes.append(f"{n_dup} repeated time stamps: the first value of each was kept")
    if not in_order:
        notes.append("rows were not in time order; they were sorted")
    return CameraSeries(time_ns=t, value_mm=v, source=str(path), column=column, unit=unit,
                        bad_rows=tuple(sorted(tab.bad, key=lambda b: b.line)), n_bad=tab.n_bad,
                        n_missing=int(np.isnan(v).sum()), n_duplicates=n_dup, gaps=gaps, sampling_s=sampling,
                        notes=tuple(notes))


def _add_bad(bad: list, mask: np.ndarray, line_no: np.ndarray, reason) -> int:
    """List the rows of ``mask`` as bad (up to :data:`MAX_BAD_LISTED` in all); returns how many there are."""
    for j in np.nonzero(mask)[0][:max(0, MAX_BAD_LISTED - len(bad))]:
        bad.append(BadRow(int(line_no[j]), reason(j)))
    return int(np.count_nonzero(mask))


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _parse_times(raw, timezone: str) -> tuple[np.ndarray, np.ndarray]:
    """Parse time strings to UTC ns; strings with an offset keep it, naive ones take ``timezone``."""
    import pandas as pd

    pattern = r"(?:Z|[+-]\d\d:?\d\d)$"
    head = raw.iloc[:200].str.contains(pattern, regex=True)
    if head.all() or not head.any():  # consistent files: decide once, rows that differ end up bad
        has_offset = np.full(len(raw), bool(head.all()))
    else:
        has_offset = raw.str.contains(pattern, regex=True).to_numpy()
    t_ns = np.zeros(len(raw), np.int64)
    ok = np.zeros(len(raw), bool)
    if has_offset.any():
        p = pd.to_datetime(raw[has_offset], utc=True, errors="coerce", format="ISO8601")
        ok[has_offset] = p.notna().to_numpy()
        t_ns[has_offset] = np.where(ok[has_offset], p.dt.as_unit("ns").fillna(pd.Timestamp(0, tz="UTC"))
                                    .astype("int64").to_numpy(), 0)
    naive = ~has_offset
    if naive.any():
        p = pd.to_datetime(raw[naive], errors="coerce", format="ISO8601")
        if p.isna().mean() > 0.5:
            p = pd.to_datetime(raw[naive], errors="coerce", format="mixed")
        try:
            p = p.dt.tz_localize(_zone(timezone), ambiguous="NaT", nonexistent="NaT")
        except (ValueError, TypeError) as exc:
            raise InputError(f"time zone {timezone!r} is not known ({exc})") from None
        good = p.notna().to_numpy()
        ok[naive] = good
        t_ns[naive] = np.where(good, p.dt.tz_convert("UTC").dt.as_unit("ns").fillna(pd.Timestamp(0, tz="UTC"))
                               .astype("int64").to_numpy(), 0)
    return t_ns, ok


def _zone(name: str):

    m = re.fullmatch(r"(?:UTC)?([+-])(\d\d):?(\d\d)", name.strip())
    if m:
        sign = 1 if m.group(1) == "+" else -1
        return dt.timezone(sign * dt.timedelta(hours=int(m.group(2)), minutes=int(m.group(3))))
    return "UTC" if name.strip().upper() in ("UTC", "Z", "GMT") else name.strip()


def _times_with_zone_column(raw, zones) -> tuple[np.ndarray, np.ndarray]:
    """Times whose zone is given per row: parse each distinct zone's rows together."""
    t_ns = np.zeros(len(raw), np.int64)
    ok = np.zeros(len(raw), bool)
    zv = zones.to_numpy()
    for z in np.unique(zv):
        sel = zv == z
        try:
            t, good = _parse_times(raw[sel], z or "UTC")
        except InputError:
            continue  # an unknown zone: those rows are bad
        t_ns[sel], ok[sel] = t, good
    return t_ns, ok

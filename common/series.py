"""Read a time series file (CSV or text): camera displacements, temperatures, humidity, rain...

One reader for every series a surveyor imports; what the values are comes from a :class:`Quantity`
(the names of its column, its units and the unit stored).

What is understood
------------------
* Separators: comma, semicolon, tab or runs of spaces, told by the header row (the separator that
  splits it is the one the data rows mostly share). Lines starting with ``#`` and blank lines are skipped.
* Decimal commas (``12,5``) in files separated by semicolons, tabs or spaces.
* A header row naming the columns (case-insensitive):
  - time: ``timestamp``, ``datetime``, ``time``, ``date`` (or separate ``date`` and ``time``
    columns), ISO 8601 or ``YYYY-MM-DD hh:mm[:ss]``, or Unix seconds (``unix``, ``epoch_s``);
  - value: by the quantity's names, with an optional unit in the name (``displacement_mm``,
    ``humidity_pct``, ``temp [degC]``); the one column left when no name tells; or chosen by name;
  - optional ``unit`` column (per row) and ``tz``/``timezone``/``utc_offset`` column (``+09:00``,
    ``UTC``, ``Asia/Seoul``).
* Empty cells, ``NaN``, ``NA``, ``null`` and ``-`` are gaps (kept as missing values).
* Rows whose time or value cannot be read, or with the wrong number of fields, are *bad rows*:
  left out, counted and reported with their line numbers. A file is refused only when no row is left.

Times are stored as UTC (int64 nanoseconds); times without an offset take the ``timezone`` argument,
and the series says which zone it assumed (:attr:`Series.times_read`).
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

#: Version of the stored arrays (:func:`series_npz_bytes`): 1 named the values ``value_mm`` whatever they were.
SERIES_FORMAT_VERSION = 2
NAN_TOKENS = {"", "nan", "na", "n/a", "null", "none", "-", "--"}
TIME_NAMES = ("timestamp", "datetime", "date_time", "time_utc", "time", "date")
UNIX_NAMES = ("unix", "unix_s", "epoch_s", "posix", "unixtime")
UNIT_NAMES = ("unit", "units")
TZ_NAMES = ("tz", "timezone", "time_zone", "utc_offset", "offset")
MAX_BAD_LISTED = 1000  # bad rows kept with their line numbers (all are counted)
_SEPARATORS = ("\t", ";", ",")


@dataclass(frozen=True)
class Quantity:
    """What a series file's value column holds, for the reader.

    Attributes
    ----------
    noun : str
        For messages ("relative humidity").
    value_names : tuple of str
        Column names to look for, best first.
    units : dict
        ``name -> (scale, offset)`` into the stored unit (``stored = value * scale + offset``).
    default_unit : str
        The file's unit when neither the column name, a unit column nor the caller tells.
    stored_unit : str
        The unit of :attr:`Series.values`.
    signed : bool
        Whether ``positive='down'`` may flip it.
    """

    noun: str
    value_names: tuple[str, ...]
    units: dict
    default_unit: str
    stored_unit: str
    signed: bool = True


class SeriesFormatError(SurveyError):
    """A series file cannot be read."""

    def __init__(self, path, problem: str):
        super().__init__(f"{path}: {problem}")


@dataclass(frozen=True)
class BadRow:
    """A row of a series file that could not be read: its line number and why."""

    line: int
    reason: str


@dataclass(frozen=True)
class Series:
    """A series of values in its quantity's stored unit at UTC times.

    Attributes
    ----------
    time_ns : (n,) int64 UTC nanoseconds, increasing.
    values : (n,) float64 in ``unit``; NaN marks a gap value (the row was there but empty).
    unit : the unit of ``values`` (the quantity's stored unit).
    unit_read : the unit the file's values were in.
    source : the file it came from; ``column`` the value column used.
    bad_rows : rows left out, with line numbers (the first ``MAX_BAD_LISTED``), ``n_bad`` their count, of
        ``n_rows`` data rows in the file.
    gaps : (start_ns, end_ns) of pauses longer than ``gap_factor`` sampling intervals.
    sampling_s : median sampling interval in seconds.
    times_read : how the times were read, naming the zone assumed for times without an offset.
    """

    time_ns: np.ndarray
    values: np.ndarray
    unit: str
    unit_read: str = ""
    source: str = ""
    column: str = ""
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
        """What the import found, for the command line, the application and the stored record."""
        def iso(ns):
            return dt.datetime.fromtimestamp(int(ns) / 1e9, dt.UTC).isoformat()

        return {"rows": len(self), "start": iso(self.time_ns[0]) if len(self) else None,
                "end": iso(self.time_ns[-1]) if len(self) else None, "sampling_s": self.sampling_s,
                "missing_values": self.n_missing, "bad_rows": self.n_bad, "rows_in_file": self.n_rows,
                "duplicates_dropped": self.n_duplicates, "gaps": len(self.gaps), "column": self.column,
                "unit": self.unit, "unit_read": self.unit_read, "times": self.times_read,
                "first_bad_lines": [f"line {b.line}: {b.reason}" for b in self.bad_rows[:10]],
                "notes": list(self.notes)}


def _pandas():
    """The pandas module, imported at its first use."""
    # local: pandas costs status and the other campaign commands 0.15-0.18 s of start-up (measured)
    import pandas

    return pandas


def series_npz_bytes(time_ns: np.ndarray, values: np.ndarray) -> bytes:
    """The stored form of a series' arrays (compressed npz with its format version)."""
    buf = io.BytesIO()
    np.savez_compressed(buf, version=np.int64(SERIES_FORMAT_VERSION), time_ns=time_ns, values=values)
    return buf.getvalue()


def series_arrays_from_npz(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """``(time_ns, values)`` of :func:`series_npz_bytes` (version 1 too); a newer version is refused."""
    with np.load(io.BytesIO(data)) as z:
        version = int(z["version"])
        if version > SERIES_FORMAT_VERSION:
            raise InputError(f"series stored by a newer BridgeSurvey (format {version}); update it")
        values = z["values"] if version >= 2 else z["value_mm"]
        return z["time_ns"].astype(np.int64), values.astype(np.float64)


def zone_of(name: str) -> Any:
    """The time zone called ``name``: an IANA name (returned as is), ``UTC``, or an offset ``+hh:mm``."""
    m = re.fullmatch(r"(?:UTC)?([+-])(\d\d):?(\d\d)", name.strip())
    if m:
        sign = 1 if m.group(1) == "+" else -1
        return dt.timezone(sign * dt.timedelta(hours=int(m.group(2)), minutes=int(m.group(3))))
    return "UTC" if name.strip().upper() in ("UTC", "Z", "GMT") else name.strip()


def check_zone(name: str) -> str:
    """``name`` stripped when it is a time zone (IANA name or ``+hh:mm``); an :class:`InputError` when not."""
    pd = _pandas()
    try:
        pd.Timestamp("2026-01-01").tz_localize(zone_of(name))
    except Exception:  # pytz/zoneinfo raise several types for unknown zones
        raise InputError(f"time zone {name!r} is not known; use an IANA name such as Europe/Berlin or an "
                         "offset such as +09:00") from None
    return name.strip()


def read_series(path: str | os.PathLike, *, quantity: Quantity, column: str | None = None, timezone: str = "UTC",
                unit: str | None = None, positive: str = "up", gap_factor: float = 3.0) -> Series:
    """Read a series file (see the module documentation for what is understood).

    It runs in stages: the options are checked, the text is split into a table
    (:func:`_read_table`), the time and value columns are found (:func:`_find_columns`), the times
    (:func:`_read_times`) and values (:func:`_read_values`) are parsed with every bad row listed, and
    the series is put in time order with its gaps and repeats noted (:func:`_assemble`).

    Parameters
    ----------
    path : CSV or text file.
    quantity : what the values are: the column names to look for and the units.
    column : name of the value column when the header does not tell.
    timezone : for times without an offset and no time-zone column (IANA name or ``+hh:mm``; default UTC).
    unit : the values' unit when neither the column name nor a unit column tells (default the quantity's).
    positive : ``up`` (default) or ``down`` -- the file's sign convention, for a signed quantity.
    gap_factor : a pause longer than this many median sampling intervals is reported as a gap.

    Returns
    -------
    Series
        The rows read; the bad rows are counted and listed, never a reason to refuse the file unless no row is left.
    """
    path = Path(path)
    check_zone(timezone)
    if positive not in ("up", "down"):
        raise InputError(f"positive must be 'up' or 'down', not {positive!r}")
    if not path.is_file():
        raise InputError(f"{path}: no such file; check the path")
    tab = _read_table(path)
    cols = _find_columns(path, tab.header, column, quantity)
    t_ns, t_ok, times_read = _read_times(tab, cols, timezone)
    vals, missing, scale, offset, v_ok, file_unit = _read_values(path, tab, cols, t_ok, unit, quantity)
    good = t_ok & v_ok
    if good.sum() == 0:
        first = min(tab.bad, key=lambda b: b.line) if tab.bad else None
        raise SeriesFormatError(path, f"no readable rows ({tab.n_bad} bad; first: "
                                f"{first.reason if first else 'none'} at line {first.line if first else '?'})")
    sign = 1.0 if positive == "up" or not quantity.signed else -1.0
    v = np.where(missing[good], np.nan, (vals[good] * scale[good] + offset[good]) * sign)
    return _assemble(path, tab, t_ns[good], v, tab.header[cols.value], quantity.stored_unit, file_unit, gap_factor,
                     times_read)


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


def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9µ%°]+", "_", name.strip().lower()).strip("_")


def _unit_in_name(name: str, units: dict) -> str | None:
    alt = "|".join(sorted((re.escape(u) for u in units), key=len, reverse=True))
    m = re.search(rf"(?:[_\[\(\s]|^)({alt})(?:[\]\)\s]|$)", name.strip().lower())
    if m is None:
        m = re.search(rf"_({alt})$", _norm(name))
    return m.group(1) if m else None


def _find(names: list[str], wanted) -> int | None:
    normed = [_norm(n) for n in names]
    for w in wanted:
        for i, n in enumerate(normed):
            if n and (n == w or n.startswith(w + "_")):
                return i
    return None


def sniff_separator(lines: list[str]) -> str | None:
    """The separator of a table whose first line is the header (None: runs of spaces).

    The header decides: of the separators that split it, the one whose count in the header most data rows share
    (so a semicolon file with decimal commas is split at its semicolons, and a bad row does not change the answer).
    """
    header, sample = lines[0], lines[1:51] or lines[:1]
    best, best_share = None, 0.0
    for sep in _SEPARATORS:
        n = header.count(sep)
        if n == 0:
            continue
        share = sum(ln.count(sep) == n for ln in sample) / len(sample)
        if share > best_share:
            best, best_share = sep, share
    return best


def _read_table(path: Path) -> _Table:
    """The header and the rows of a series file; rows with the wrong field count are listed as bad."""
    pd = _pandas()
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError:
        raise SeriesFormatError(path, "not a text file (CSV or TXT expected)") from None
    all_lines = text.splitlines()
    keep = [i for i, ln in enumerate(all_lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not keep:
        raise SeriesFormatError(path, "no data rows")
    lines = [all_lines[i] for i in keep]
    sep = sniff_separator(lines)
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
    n_bad = _add_bad(bad, ~ok_fields, np.asarray(body_lines) + 1,
                     lambda j: _fields_reason(_fields(body[j], sep), ncol))
    good_idx = np.nonzero(ok_fields)[0]
    data = "\n".join(body[j] for j in good_idx)
    try:
        df = pd.read_csv(io.StringIO(data), sep=sep if sep else r"\s+", header=None, names=list(range(ncol)),
                         dtype=str, keep_default_na=False, engine="c" if sep else "python", quotechar='"')
    except Exception as exc:  # pandas' parser errors have many types
        raise SeriesFormatError(path, f"cannot be parsed as a table ({str(exc).splitlines()[0]})") from None
    line_no = np.asarray(body_lines, dtype=np.int64)[good_idx] + 1
    return _Table(header, df, line_no, sep, len(body), bad, n_bad)


def _fields(line: str, sep: str | None) -> int:
    return len(line.split(sep)) if sep else len(line.split())


def _fields_reason(k: int, ncol: int) -> str:
    return f"{k} field{'' if k == 1 else 's'} where the header has {ncol} fields"


def _find_columns(path: Path, header: list[str], column: str | None, quantity: Quantity) -> _Columns:
    """Which column holds the time, the unit, the time zone and the value.

    The time is unix seconds, a date-time, or a date and a clock; the value is ``column`` when given, else the
    first of the quantity's names, else the one column left.
    """
    columns = ", ".join(header)
    v_given = None
    if column is not None:
        matches = [i for i, h in enumerate(header) if h == column or _norm(h) == _norm(column)]
        if not matches:
            raise InputError(f"{path}: no column {column!r}; the columns are {columns}")
        v_given = matches[0]
    named = [h if i != v_given else "" for i, h in enumerate(header)]
    t_unix = _find(named, UNIX_NAMES)
    t_col = _find(named, TIME_NAMES)
    date_col, clock_col = _find(named, ("date",)), _find(named, ("time", "clock"))
    unit_col = _find(named, UNIT_NAMES)
    tz_col = _find(named, TZ_NAMES)
    used = {i for i in (t_unix, t_col, date_col, clock_col, unit_col, tz_col) if i is not None}
    if t_unix is None and t_col is None:
        raise SeriesFormatError(path, f"no time column (one of {', '.join(TIME_NAMES + UNIX_NAMES)}); "
                                f"the columns are {columns}")
    if v_given is not None:
        return _Columns(t_unix, t_col, date_col, clock_col, unit_col, tz_col, v_given)
    found = _find([h if i not in used else "" for i, h in enumerate(header)], quantity.value_names)
    if found is None:
        candidates = [i for i in range(len(header)) if i not in used]
        if len(candidates) != 1:
            raise InputError(f"{path}: cannot tell which column holds the {quantity.noun} (the columns are "
                             f"{columns}); name it with --column")
        found = candidates[0]
    return _Columns(t_unix, t_col, date_col, clock_col, unit_col, tz_col, found)


def _read_times(tab: _Table, cols: _Columns, timezone: str) -> tuple[np.ndarray, np.ndarray, str]:
    """(UTC nanoseconds, readable mask, how they were read) of every row; unreadable times are listed as bad rows."""
    pd = _pandas()
    df = tab.df
    if cols.unix is not None:
        secs = pd.to_numeric(df[cols.unix].str.strip(), errors="coerce").to_numpy(float)
        t_ok = np.isfinite(secs)
        t_ns = np.where(t_ok, np.round(np.nan_to_num(secs) * 1e9), 0).astype(np.int64)
        read = "Unix seconds (UTC)"
    else:
        raw = df[cols.time].str.strip()
        if cols.date is not None and cols.clock is not None and cols.date != cols.clock:
            raw = df[cols.date].str.strip() + " " + df[cols.clock].str.strip()
        if cols.zone is not None:
            t_ns, t_ok = _times_with_zone_column(raw, df[cols.zone].str.strip())
            read = f"in the zone of each row ('{tab.header[cols.zone]}' column)"
        else:
            t_ns, t_ok, n_naive = _parse_times(raw, timezone)
            n = len(raw)
            read = ("with their UTC offsets" if n_naive == 0 else
                    f"without an offset, read as {timezone} time" if n_naive == n else
                    f"{n_naive} of {n} without an offset, read as {timezone} time; the others with their offsets")
    t_of = cols.unix if cols.unix is not None else cols.time
    tab.n_bad += _add_bad(tab.bad, ~t_ok, tab.line_no, lambda j: f"time {df.iat[j, t_of]!r} is not a date-time")
    return t_ns, t_ok, read


def _read_values(path: Path, tab: _Table, cols: _Columns, t_ok: np.ndarray, unit: str | None, quantity: Quantity):
    """(values, missing mask, scale and offset to the stored unit per row, readable mask, unit text).

    Values and units that cannot be read are listed as bad rows; a decimal comma is read as a point unless the
    file is separated by commas.
    """
    pd = _pandas()
    df = tab.df
    vraw = df[cols.value].str.strip()
    missing = vraw.str.lower().isin(NAN_TOKENS).to_numpy()
    vals = pd.to_numeric(vraw.str.replace(",", ".", regex=False) if tab.sep != "," else vraw,
                         errors="coerce").to_numpy(float)
    v_bad = ~missing & ~np.isfinite(vals) & t_ok
    table = quantity.units
    file_unit = unit or _unit_in_name(tab.header[cols.value], table) or quantity.default_unit
    if file_unit.lower() not in table:
        raise InputError(f"{path}: unknown unit {file_unit!r} for the {quantity.noun}; use one of "
                         f"{', '.join(table)}")
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


def _assemble(path: Path, tab: _Table, t: np.ndarray, v: np.ndarray, column: str, unit: str, unit_read: str,
              gap_factor: float, times_read: str) -> Series:
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
    if tab.n_bad:
        notes.append(f"{tab.n_bad} of {tab.n_rows} rows could not be read and were left out")
    if n_dup:
        notes.append(f"{n_dup} repeated time stamps: the first value of each was kept")
    if not in_order:
        notes.append("rows were not in time order; they were sorted")
    return Series(time_ns=t, values=v, unit=unit, unit_read=unit_read, source=str(path), column=column,
                  bad_rows=tuple(sorted(tab.bad, key=lambda b: b.line)), n_bad=tab.n_bad, n_rows=tab.n_rows,
                  n_missing=int(np.isnan(v).sum()), n_duplicates=n_dup, gaps=gaps, sampling_s=sampling,
                  times_read=times_read, notes=tuple(notes))


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


def _parse_times(raw, timezone: str) -> tuple[np.ndarray, np.ndarray, int]:
    """Parse time strings to UTC ns; strings with an offset keep it, naive ones take ``timezone``.

    Returns the times, which were readable, and how many were taken as naive.
    """
    pd = _pandas()
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
            p = p.dt.tz_localize(zone_of(timezone), ambiguous="NaT", nonexistent="NaT")
        except (ValueError, TypeError) as exc:
            raise InputError(f"time zone {timezone!r} is not known ({exc})") from None
        good = p.notna().to_numpy()
        ok[naive] = good
        t_ns[naive] = np.where(good, p.dt.tz_convert("UTC").dt.as_unit("ns").fillna(pd.Timestamp(0, tz="UTC"))
                               .astype("int64").to_numpy(), 0)
    return t_ns, ok, int(naive.sum())


def _times_with_zone_column(raw, zones) -> tuple[np.ndarray, np.ndarray]:
    """Times whose zone is given per row: parse each distinct zone's rows together."""
    t_ns = np.zeros(len(raw), np.int64)
    ok = np.zeros(len(raw), bool)
    zv = zones.to_numpy()
    for z in np.unique(zv):
        sel = zv == z
        try:
            t, good, _ = _parse_times(raw[sel], z or "UTC")
        except InputError:
            continue  # an unknown zone: those rows are bad
        t_ns[sel], ok[sel] = t, good
    return t_ns, ok

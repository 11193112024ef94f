"""The design prediction of each target's displacement (a finite-element model's curve).

It is aligned to the measurements at a date or by least squares, and how far the measurements depart from it.

File: CSV/text with a header. Time is a ``date`` (ISO 8601) column or an ``age_days`` column (days
since casting; the campaign needs ``settings DIR casting_date ISO``). Values in mm, positive up:
either one column per target named by its id (wide), or ``reflector`` and ``value_mm`` columns
(long). Targets the campaign does not have are refused.
"""
from __future__ import annotations

import datetime as dt
import io
import os
from pathlib import Path

import numpy as np

from common.errors import InputError
from common.files import sha256_of
from projects.store.campaign import PREDICTION_DIR, Campaign, parse_datetime
from projects.store.history import histories

DAY_NS = 86_400 * 10**9
FORMAT_VERSION = 1


def casting_ns(c: Campaign) -> int | None:
    """The casting date setting as nanoseconds since 1970 (UTC), or None when it is not set."""
    s = c.settings().get("casting_date")
    return None if not s else int(dt.datetime.fromisoformat(s).timestamp() * 1e9)


def read_prediction_file(path: Path, reflector_ids, casting: int | None) -> tuple[dict, str]:
    """``{reflector: (time_ns, value_mm)}`` and the time axis used (``date`` or ``age``)."""
    # local: pandas costs status and the other campaign commands 0.15-0.18 s of start-up (measured)
    import pandas as pd

    try:
        text = path.read_text(encoding="utf-8-sig")
        df = pd.read_csv(io.StringIO(text), sep=None, engine="python", comment="#")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the prediction ({exc})") from None
    except Exception as exc:  # pandas parser errors
        raise InputError(f"{path}: not a table ({str(exc).splitlines()[0]})") from None
    cols = {str(c).strip().lower(): c for c in df.columns}
    if "date" in cols:
        try:
            t = pd.to_datetime(df[cols["date"]], utc=True).dt.tz_localize(None).to_numpy(
                dtype="datetime64[ns]").astype(np.int64)
        except (ValueError, TypeError):
            raise InputError(f"{path}: the date column holds something that is not a date") from None
        axis = "date"
    elif "age_days" in cols:
        if casting is None:
            raise InputError(f"{path}: the prediction is by concrete age; set the casting date first "
                             "('bridgesurvey settings DIR casting_date 2017-09-16')")
        age = pd.to_numeric(df[cols["age_days"]], errors="coerce").to_numpy(float)
        if not np.all(np.isfinite(age)):
            raise InputError(f"{path}: age_days must be numbers")
        t = (casting + age * DAY_NS).astype(np.int64)
        axis = "age"
    else:
        raise InputError(f"{path}: no time column: name it 'date' (ISO 8601) or 'age_days' (days since casting)")
    known = set(reflector_ids)
    out = {}
    if "reflector" in cols:
        vcol = next((cols[k] for k in ("value_mm", "displacement_mm", "value") if k in cols), None)
        if vcol is None:
            raise InputError(f"{path}: a long table needs a value_mm column beside reflector")
        groups = {str(r).strip(): idx for r, idx in df.groupby(cols["reflector"]).groups.items()}
        wanted = groups
    else:
        wanted = {str(c).strip(): None for c in df.columns if str(c).strip().lower() not in ("date", "age_days")}
        vcol = None
    unknown = sorted(set(wanted) - known)
    if unknown:
        raise InputError(f"{path}: targets {', '.join(unknown)} are not in the campaign "
                         f"({', '.join(sorted(known))}); rename the columns or remove them")
    if not wanted:
        raise InputError(f"{path}: no target column")
    for rid, idx in wanted.items():
        if vcol is None:
            v = pd.to_numeric(df[next(c for c in df.columns if str(c).strip() == rid)], errors="coerce").to_numpy(float)
            tt = t
        else:
            sub = df.loc[idx]
            v = pd.to_numeric(sub[vcol], errors="coerce").to_numpy(float)
            tt = t[np.asarray(idx)]
        ok = np.isfinite(v)
        if ok.sum() < 2:
            raise InputError(f"{path}: target {rid} has fewer than two predicted values")
        order = np.argsort(tt[ok])
        out[rid] = (tt[ok][order].astype(np.int64), v[ok][order])
    return out, axis


def align(t_pred, v_pred, t_meas, d_meas, s_meas, *, at_ns: int | None = None) -> tuple[float, float, int]:
    """(offset_mm, residual RMS mm, pairs): measured = predicted + offset, at one date or by least squares."""
    inside = (t_meas >= t_pred[0]) & (t_meas <= t_pred[-1])
    if not np.any(inside):
        raise InputError("the prediction does not overlap the measured epochs")
    p = np.interp(t_meas[inside], t_pred, v_pred)
    d, s = d_meas[inside], s_meas[inside]
    if at_ns is not None:
        k = int(np.argmin(np.abs(t_meas[inside] - at_ns)))
        if abs(int(t_meas[inside][k]) - at_ns) > 14 * DAY_NS:
            raise InputError("no measured epoch within two weeks of the alignment date")
        offset = float(d[k] - p[k])
    else:
        w = 1.0 / np.maximum(s, 0.05) ** 2
        offset = float(np.sum(w * (d - p)) / np.sum(w))
    resid = d - (p + offset)
    return offset, float(np.sqrt(np.mean(resid ** 2))), int(inside.sum())


def import_prediction(c: Campaign, path: str | os.PathLike, *, align_at: str | None = None,
                      lsq: bool = False) -> dict:
    """Read a prediction file, align every target in it, copy the file in and store the curves.

    Aligned at the epoch nearest ``align_at`` (within two weeks), else by weighted least squares over
    every epoch the prediction covers (also the default).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file; check the path")
    if align_at and lsq:
        raise InputError("align at a date or by least squares, not both")
    reflectors = c.reflectors()
    meas_ids = [r.id for r in reflectors if not r.is_reference]
    curves, axis = read_prediction_file(path, [r.id for r in reflectors], casting_ns(c))
    at_ns = None
    if align_at:
        at_ns = int(dt.datetime.fromisoformat(parse_datetime(align_at)).timestamp() * 1e9)
    out = {}
    measured = {rid: h.measured() for rid, h in histories(c).items()}
    for rid, (t, v) in curves.items():
        if rid not in meas_ids:
            raise InputError(f"{path}: {rid} is a reference target; predictions are for deck targets")
        h = measured.get(rid)
        tm, dm, sm = (h.time_ns, h.displacement_mm, h.sigma_mm) if h is not None else (np.zeros(0),) * 3
        if not len(tm):
            raise InputError(f"{path}: {rid} has no measured displacement yet; process the campaign first")
        try:
            offset, rms, n = align(t, v, tm, dm, sm, at_ns=at_ns)
        except InputError as exc:
            raise InputError(f"{path}: {rid}: {exc}") from None
        out[rid] = {"offset_mm": offset, "residual_rms_mm": rms, "pairs": n}
    sha = sha256_of(path)

    def record(conn, rel):
        for rid, (t, v) in curves.items():
            buf = io.BytesIO()
            np.savez_compressed(buf, version=np.int64(FORMAT_VERSION), time_ns=t, value_mm=v)
            options = {"axis": axis, "align_at": align_at, "lsq": lsq, **out[rid]}
            c.predictions.put(conn, rid, sha256=sha, stored_path=rel, original_path=str(path.resolve()),
                                options=options, arrays=buf.getvalue())
        c.log_action(conn, "prediction-import", None, {"file": str(path), "sha256": sha, "targets": sorted(curves),
                                                 "align_at": align_at, "lsq": lsq})

    c.import_file(path, sha, PREDICTION_DIR, record, journal_entry={  # what 'repair' needs to read it again
        "kind": "prediction", "read": {"align_at": align_at, "lsq": lsq}})
    return out


def predictions(c: Campaign) -> dict:
    """``{reflector: (time_ns, value_mm aligned, options)}``."""
    out = {}
    for r in c.predictions.all():
        with np.load(io.BytesIO(r.arrays)) as z:
            if int(z["version"]) > FORMAT_VERSION:
                raise InputError("a prediction stored by a newer BridgeSurvey; update it")
            opts = r.options
            out[r.reflector] = (z["time_ns"].astype(np.int64), z["value_mm"] + opts["offset_mm"], opts)
    return out

"""Exports of a campaign: displacement table (CSV/JSON) and a workbook of everything (XLSX)."""
from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path

import numpy as np

from common.files import write_atomic  # noqa: F401  (part of this module's API)
from projects.store import Campaign

DISPLACEMENT_COLUMNS = ["epoch", "datetime", "reflector", "displacement_mm", "sigma_mm", "flags", "state",
                        "warning_mm", "alarm_mm", "baseline", "epoch_flags", "days_from_baseline", "severity",
                        "concrete_age_days", "predicted_mm", "departure_mm"]


def displacement_table(c: Campaign) -> list[dict]:
    """One row per processed epoch x measurement target (baseline = first epoch, positive up)."""
    from datetime import datetime

    from lidar.flags import worst

    from projects.predictions import predictions

    when = {e.label: e.when for e in c.epochs()}
    settings = c.settings()
    casting = datetime.fromisoformat(settings["casting_date"]) if settings.get("casting_date") else None
    preds = predictions(c)
    tols = settings.get("prediction_tolerance_mm") or {}
    rows = []
    records = c.displacements()
    limits = {rid: c.limit_for(rid) for rid in {r.reflector for r in records}}
    for r in records:
        lim = limits[r.reflector]
        mm = None if r.displacement_m is None else r.displacement_m * 1000.0
        rows.append({
            "epoch": r.epoch, "datetime": r.datetime, "reflector": r.reflector,
            "displacement_mm": None if mm is None else round(mm, 4) + 0.0,
            "sigma_mm": None if r.sigma_m is None else round(r.sigma_m * 1000.0, 4),
            "flags": ";".join(r.flags),
            "state": lim.state(mm if mm is not None else float("nan")) if lim else ("unknown" if mm is None else "ok"),
            "warning_mm": None if lim is None else lim.warning_mm, "alarm_mm": None if lim is None else lim.alarm_mm,
            "baseline": r.baseline, "epoch_flags": ";".join(r.epoch_flags),
            # negative for an epoch dated before the baseline
            "days_from_baseline": round((when[r.epoch] - when[r.baseline]).total_seconds() / 86400.0, 4)
            if r.baseline in when else None,
            "severity": worst(r.flags + r.epoch_flags) or "",
            "concrete_age_days": None if casting is None else
            round((when[r.epoch] - casting).total_seconds() / 86400.0, 3),
            "predicted_mm": None, "departure_mm": None,
        })
        p = preds.get(r.reflector)
        t_ns = int(when[r.epoch].timestamp() * 1e9)
        if p is not None and p[0][0] <= t_ns <= p[0][-1]:
            pred = float(np.interp(t_ns, p[0], p[1]))
            row = rows[-1]
            row["predicted_mm"] = round(pred, 4)
            if mm is not None:
                row["departure_mm"] = round(mm - pred, 4)
                tol = tols.get(r.reflector, tols.get("*"))
                if tol is not None and abs(mm - pred) > tol:
                    row["flags"] = ";".join(f for f in (row["flags"], "departs_from_prediction") if f)
                    row["severity"] = worst(row["flags"].split(";") + list(r.epoch_flags)) or ""
    return rows


def to_csv(rows: list[dict], columns=DISPLACEMENT_COLUMNS) -> str:
    """Rows as CSV text with the given columns (missing values as empty cells)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in columns})
    return buf.getvalue()


def tables(c: Campaign) -> dict[str, list[dict]]:
    """Every table a surveyor may want, as lists of rows."""
    cents = []
    epochs = c.epochs()
    for e in epochs:
        for rid, t in c.centroids(e.label).items():
            sig = np.sqrt(np.clip(np.diag(t.cov), 0, None)) * 1000
            cents.append({"epoch": e.label, "reflector": rid, "found": t.found,
                          "x_m": t.xyz_socs[0], "y_m": t.xyz_socs[1], "z_m": t.xyz_socs[2],
                          "sx_mm": sig[0], "sy_mm": sig[1], "sz_mm": sig[2], "n_points": t.n_points,
                          "threshold": t.threshold, "separability": t.separability, "flags": ";".join(t.flags)})
    epoch_rows = []
    for e in epochs:
        res = c.result(e.label)
        epoch_rows.append({"epoch": e.label, "datetime": e.datetime, "notes": e.notes,
                           "coarse_files": len(c.files(e.label, "coarse")), "fine_files": len(c.files(e.label, "fine")),
                           "stage": res.stage if res else "imported"})
    log = [{**entry.to_dict(), "details": json.dumps(entry.details, default=str)} for entry in c.log()]
    return {"epochs": epoch_rows, "reflectors": [r.to_dict() for r in c.reflectors()], "centroids": cents,
            "displacements": displacement_table(c),
            "files": [f.to_dict() for e in epochs for f in c.files(e.label)], "log": log}


def export(c: Campaign, path: str | os.PathLike) -> Path:
    """Write every table: an XLSX workbook (one sheet each) or, for .csv, the displacement table."""
    p = Path(path)
    if p.suffix.lower() == ".csv":
        return write_atomic(p, to_csv(displacement_table(c)))
    if p.suffix.lower() != ".xlsx":
        from common.errors import InputError

        raise InputError(f"{p}: export writes .xlsx (all tables) or .csv (displacements)")
    from openpyxl import Workbook

    wb = Workbook()
    wb.remove(wb.active)
    for name, rows in tables(c).items():
        ws = wb.create_sheet(name)
        cols = list(rows[0].keys()) if rows else ["(empty)"]
        ws.append(cols)
        for r in rows:
            ws.append([_cell(r.get(k)) for k in cols])
    buf = io.BytesIO()
    wb.save(buf)
    return write_atomic(p, buf.getvalue())


def _cell(v):
    if isinstance(v, (np.floating, float)):
        return None if not np.isfinite(v) else float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    return v

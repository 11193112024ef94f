"""Exports of a campaign: a workbook of every table (XLSX), or the displacement table as CSV."""
from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np

from common.errors import InputError
from common.files import write_atomic
from projects.results.state import epoch_states
from projects.results.table import displacement_table, to_csv
from projects.store.campaign import Campaign


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
    states = epoch_states(c)  # as 'status' and the campaign tree give them, read once for every epoch
    for e in epochs:
        state, flags = states[e.label].state, states[e.label].flags
        epoch_rows.append({"epoch": e.label, "datetime": e.datetime, "notes": e.notes,
                           "coarse_files": len(c.files(e.label, "coarse")), "fine_files": len(c.files(e.label, "fine")),
                           "state": state, "flags": ";".join(flags)})
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

        raise InputError(f"{p}: export writes .xlsx (all tables) or .csv (displacements)")

    # local: openpyxl costs status, displacements and the application 0.11 s of start-up (measured)
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

"""The displacement table: one row per processed epoch x measurement target, with state and limits.

The single source of the rows that ``displacements``, the exports, the report, ``status`` and the camera
cross-check print (columns: :data:`DISPLACEMENT_COLUMNS`). ``state`` is the target's limit state (ok,
warning, alarm, unknown); ``epoch_state`` its epoch's state as ``status`` shows it
(:func:`projects.results.state.decide_state`: processed, warning or problem, from every flag of the epoch,
its centroid flags included).
"""
from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime

from common.files import csv_text
from common.flags import FLAG_DEPARTS, worst
from common.numbers import written
from projects.results.state import EpochState, departures, epoch_states
from projects.store.campaign import Campaign

DISPLACEMENT_COLUMNS = ["epoch", "datetime", "reflector", "displacement_mm", "sigma_mm", "flags", "state",
                        "warning_mm", "alarm_mm", "baseline", "epoch_flags", "days_from_baseline", "severity",
                        "concrete_age_days", "predicted_mm", "departure_mm", "along_mm", "along_sigma_mm",
                        "scale_ppm", "scale_sigma_ppm", "sigma_noise_mm", "sigma_frame_mm", "sigma_scale_mm",
                        "sigma_bias_mm", "sigma_drift_mm", "epoch_state"]
#: The error budget's terms as columns: a displacement's sigma is their sum in quadrature.
BUDGET_COLUMNS = ("sigma_noise_mm", "sigma_frame_mm", "sigma_scale_mm", "sigma_bias_mm", "sigma_drift_mm")


def _mm(v) -> object:
    return None if v is None else round(float(v) * 1000.0, 4) + 0.0


def field_columns(r) -> dict:
    """The along-span movement, the epoch's scale and the budget of one displacement record, in mm and ppm."""
    sysm = r.systematics or {}
    out = {"along_mm": _mm(r.along_m), "along_sigma_mm": _mm(r.along_sigma_m),
           "scale_ppm": None if "scale_ppm" not in sysm else round(float(sysm["scale_ppm"]), 2) + 0.0,
           "scale_sigma_ppm": None if "scale_sigma_ppm" not in sysm else round(float(sysm["scale_sigma_ppm"]), 2)}
    for col in BUDGET_COLUMNS:
        out[col] = _mm(r.budget.get(col[6:-3]))
    if r.displacement_m is None:
        out.update({"along_mm": None, "along_sigma_mm": None, **{col: None for col in BUDGET_COLUMNS}})
    return out


def displacement_table(c: Campaign, *, states: Mapping[str, EpochState] | None = None) -> list[dict]:
    """One row per processed epoch x measurement target (baseline = first epoch, positive up).

    ``states`` are the epochs' states when the caller has them already (default: computed here).
    """
    when = {e.label: e.when for e in c.epochs()}
    settings = c.settings()
    casting = datetime.fromisoformat(settings["casting_date"]) if settings.get("casting_date") else None
    records = c.displacements()
    departed = departures(c, records)
    states = epoch_states(c, departed=departed) if states is None else states
    limits = {rid: c.limit_for(rid) for rid in {r.reflector for r in records}}
    rows = []
    for r in records:
        lim = limits[r.reflector]
        mm = None if r.displacement_m is None else r.displacement_m * 1000.0
        dep = departed.get((r.epoch, r.reflector))
        flags = list(r.flags) + ([FLAG_DEPARTS] if dep is not None and dep.departs else [])
        rows.append({
            "epoch": r.epoch, "datetime": r.datetime, "reflector": r.reflector,
            "displacement_mm": None if mm is None else round(mm, 4) + 0.0,
            "sigma_mm": None if r.sigma_m is None else round(r.sigma_m * 1000.0, 4),
            "flags": ";".join(flags),
            "state": lim.state(mm if mm is not None else float("nan")) if lim else ("unknown" if mm is None else "ok"),
            "warning_mm": None if lim is None else lim.warning_mm, "alarm_mm": None if lim is None else lim.alarm_mm,
            "baseline": r.baseline, "epoch_flags": ";".join(r.epoch_flags),
            # negative for an epoch dated before the baseline
            "days_from_baseline": round((when[r.epoch] - when[r.baseline]).total_seconds() / 86400.0, 4)
            if r.baseline in when else None,
            "severity": worst(flags + list(r.epoch_flags)) or "",
            "concrete_age_days": None if casting is None else
            round((when[r.epoch] - casting).total_seconds() / 86400.0, 3),
            "predicted_mm": None if dep is None else round(dep.predicted_mm, 4),
            "departure_mm": None if dep is None or dep.departure_mm is None else round(dep.departure_mm, 4),
            **field_columns(r),
            "epoch_state": states[r.epoch].state if r.epoch in states else "",
        })
    return rows


def damaged_line(c: Campaign, labels=None) -> str | None:
    """The line naming epochs whose stored displacements are damaged and left out of the table (None: none is).

    ``labels`` narrows it to those epochs (default: every epoch).
    """
    bad = [lab for lab in c.damaged_displacements() if labels is None or lab in labels]
    if not bad:
        return None
    return (f"the displacements of epoch{'s' if len(bad) > 1 else ''} {', '.join(bad)} are damaged in "
            f"campaign.sqlite (they do not match the checksum stored with them) and are left out; run "
            f"'bridgesurvey process {c.folder}' to compute them again")


def to_csv(rows: list[dict], columns=DISPLACEMENT_COLUMNS) -> str:
    """Rows as CSV text with the given columns (default the displacement table's; missing values as empty cells).

    Millimetres are written to 0.001 mm (:func:`common.numbers.written`).
    """
    return csv_text(written_rows(rows), columns)


def written_rows(rows: list[dict]) -> list[dict]:
    """The rows as files for scripts hold them: millimetres to 0.001 mm (:func:`common.numbers.written`)."""
    return [{k: written(k, v) for k, v in r.items()} for r in rows]

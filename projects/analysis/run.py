"""``analyse``: fit every measurement target of a campaign and write ``analysis.json`` and figures.

Times are days from the baseline epoch. The temperature is the structure temperature when the
campaign has one, else the air temperature.
"""
from __future__ import annotations

import datetime as dt
import json
import math
import os
from pathlib import Path
from typing import cast

import numpy as np

from common.errors import InputError
from common.files import write_atomic
from lidar.figures import save_figure
from projects.analysis.expansion import fit_along, temperatures_at
from projects.analysis.figures import target_figure
from projects.analysis.models import Event, EventFit, TargetFit, first_crossing, fit_target
from projects.processing.stages import baseline_epoch
from projects.series.environment import events as stored_events
from projects.series.environment import load_env
from projects.series.predictions import casting_ns, predictions
from projects.store.campaign import Campaign
from projects.store.history import histories
from projects.store.limits import Limit

ANALYSIS_FORMAT_VERSION = 1
DAY_NS = 86_400 * 10**9


def _ns(iso: str) -> int:
    return int(dt.datetime.fromisoformat(iso).timestamp() * 1e9)


def _iso_day(origin_ns: int, t_days: float) -> str | None:
    if not math.isfinite(t_days):
        return None
    return dt.datetime.fromtimestamp((origin_ns + t_days * DAY_NS) / 1e9, dt.UTC).date().isoformat()


def _num(v: float | None, nd: int = 4) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)


def analyse_campaign(c: Campaign, *, horizon_days: float = 365.0, long_term_factor: float | None = None,
                     reference_temperature: float | None = None) -> dict:
    """The analysis of every measurement target (the ``analysis.json`` document)."""
    if not (math.isfinite(horizon_days) and 0 < horizon_days <= 36525):
        raise InputError(f"the horizon must be between 1 day and 100 years, got {horizon_days} days")
    if long_term_factor is not None and not (math.isfinite(long_term_factor) and long_term_factor >= 1):
        raise InputError(f"the long-term factor must be at least 1, got {long_term_factor}")
    hist = histories(c)
    if not hist:
        raise InputError(f"{c.folder}: no displacements yet; process the epochs first (Epoch ▸ Process in the "
                         "application, or 'bridgesurvey process DIR')")
    base = baseline_epoch(c)
    if base is None:
        raise InputError(f"{c.folder}: the campaign has no baseline epoch yet; process the epochs first")
    origin = _ns(c.epoch(base).datetime)
    series = load_env(c, kind="structure-temperature") or load_env(c, kind="temperature")
    temperature, temp_source = None, None
    if series:
        s = series[0]
        temperature = ((s.time_ns - origin) / DAY_NS, s.value)
        temp_source = f"{s.kind} series {s.name!r}"
    stored = stored_events(c)
    evs = [Event((_ns(e.date) - origin) / DAY_NS, e.label, e.kind, e.date[:10]) for e in stored]
    epoch_times = sorted({t for h in hist.values() for t in h.times})

    preds = predictions(c)
    casting = casting_ns(c)
    warnings = _aliasing_warnings(epoch_times, temperature, origin)
    along = _along_fits(c, temperature, origin, base)
    targets = []
    for rid, h in hist.items():
        mine = h.measured()
        t = (mine.time_ns - origin) / DAY_NS
        d = mine.displacement_mm
        sg = np.where(mine.sigma_mm > 0, mine.sigma_mm, np.nan)  # the baseline itself (sigma 0) carries no information
        fit = fit_target(t, d, sg, temperature=temperature, events=evs, reference_temperature=reference_temperature)
        lim = cast(Limit | None, h.limit)
        tj = _target_json(rid, fit, t, origin, horizon_days, lim, long_term_factor)
        if rid in preds:
            tj["prediction_offset_mm"] = _num(preds[rid][2]["offset_mm"])
            tj["prediction_residual_rms_mm"] = _num(preds[rid][2]["residual_rms_mm"])
            tj["prediction_alignment"] = preds[rid][2]["align_at"] or "least squares"
            tp, vp = preds[rid][0], preds[rid][1]  # the aligned design curve over the measured epochs, to draw
            keep = (tp >= mine.time_ns.min() - 30 * DAY_NS) & (tp <= mine.time_ns.max() + 30 * DAY_NS)
            step = max(1, int(keep.sum()) // 400)
            tj["prediction_curve"] = {"days": [_num(float(v), 3) for v in ((tp[keep] - origin) / DAY_NS)[::step]],
                                      "mm": [_num(float(v), 3) for v in vp[keep][::step]]}
        if casting is not None:
            tj["concrete_age_days"] = [_num(v + (origin - casting) / DAY_NS, 2) for v in fit.epoch_days]
        tj.update(along[rid].to_json() if rid in along else {})
        targets.append(tj)
    return {"format_version": ANALYSIS_FORMAT_VERSION, "campaign": c.name, "baseline": base,
            "time_origin": dt.datetime.fromtimestamp(origin / 1e9, dt.UTC).isoformat(),
            "temperature_source": temp_source, "casting_date": c.settings().get("casting_date"),
            "events": [e.to_dict() for e in stored], "warnings": warnings,
            "horizon_days": horizon_days, "long_term_factor": long_term_factor, "targets": targets}


def _along_fits(c: Campaign, temperature: tuple[np.ndarray, np.ndarray] | None, origin: int, base: str) -> dict:
    """Each deck target's along-span expansion coefficient (:mod:`projects.analysis.expansion`).

    Only where a temperature series covers its epochs; the baseline's along-span movement is zero by
    definition and left out.
    """
    if temperature is None:
        return {}
    rows: dict[str, list] = {}
    for r in c.displacements():
        if r.epoch == base or r.along_m is None or r.along_sigma_m is None:
            continue
        rows.setdefault(r.reflector, []).append(((_ns(r.datetime) - origin) / DAY_NS, r.along_m * 1e3,
                                                 r.along_sigma_m * 1e3))
    out = {}
    for rid, vals in rows.items():
        t, a, s = (np.array(v, dtype=np.float64) for v in zip(*vals, strict=False))
        out[rid] = fit_along(rid, temperatures_at(t, temperature), a, s)
    return out


def _aliasing_warnings(epoch_times: list[dt.datetime], temperature: tuple[np.ndarray, np.ndarray] | None,
                       origin: int) -> list[str]:
    out = []
    hours = np.array([e.astimezone(dt.UTC).hour + e.minute / 60 for e in epoch_times])
    if len(hours) >= 3:
        ang = hours / 24 * 2 * np.pi
        # the circular spread; the mean resultant length is clipped to 1 (every visit at the same hour rounds above)
        resultant = min(max(math.hypot(np.cos(ang).mean(), np.sin(ang).mean()), 1e-9), 1.0)
        spread = math.sqrt(-2 * math.log(resultant)) * 24 / (2 * np.pi)
        if spread > 3.0:
            out.append(f"the epochs were scanned at very different times of day (spread {spread:.1f} h): the daily "
                       "temperature swing aliases into the weekly series")
    if temperature is None:
        out.append("no temperature series: the thermal effect cannot be separated (import one with "
                   "'bridgesurvey env import DIR FILE --kind temperature')")
    return out


def _event_json(e: EventFit, long_term_factor: float | None) -> dict:
    out = {"date": e.date, "label": e.label, "kind": e.kind, "step_mm": _num(e.step_mm),
           "step_sigma_mm": _num(e.step_sigma_mm), "creep_mm": _num(e.creep_mm),
           "creep_sigma_mm": _num(e.creep_sigma_mm), "creep_final_mm": _num(e.creep_final_mm),
           "creep_coefficient": _num(e.creep_coefficient), "creep_coefficient_sigma": _num(e.creep_coefficient_sigma),
           "creep_coefficient_final": _num(e.creep_coefficient_final),
           "creep_coefficient_final_sigma": _num(e.creep_coefficient_final_sigma), "note": e.note}
    if long_term_factor and e.kind == "construction" and math.isfinite(e.step_mm):
        out["long_term_mm"] = _num(long_term_factor * e.step_mm)
    return out


def _projection_json(fit: TargetFit, t: np.ndarray, origin: int, horizon: float, lim: Limit | None
                     ) -> dict | None:
    """The model's value at the horizon and when the warning level is reached at this rate (limits to 0.1 mm)."""
    if fit.predictor is None or not len(t):
        return None
    last = float(np.max(t))
    v, s = fit.predict([last + horizon])
    proj: dict = {"date": _iso_day(origin, last + horizon), "displacement_mm": _num(v[0]), "sigma_mm": _num(s[0]),
                  "at_reference_temperature": fit.reference_temperature_degC is not None}
    if lim is None or not lim.warning_mm:
        return proj
    level = -abs(lim.warning_mm) if v[0] < 0 else abs(lim.warning_mm)
    cross = first_crossing(fit, last, last + 3652.5, level)
    if cross is None:
        proj["warning"] = f"the warning level ({lim.warning_mm:.1f} mm) is not reached within 10 years at this rate"
        return proj
    c0, early, late = cross
    proj.update(warning_level_mm=_num(level, 1), warning_date=_iso_day(origin, c0),
                warning_earliest=_iso_day(origin, early), warning_latest=_iso_day(origin, late))
    proj["warning"] = (f"at this rate the warning level ({lim.warning_mm:.1f} mm) is reached on "
                       f"{proj['warning_date'] or 'no date (only the 2-sigma band reaches it)'}"
                       f" (2 sigma: from {proj['warning_earliest']})")
    return proj


def _model_curve(fit: TargetFit, events: list[EventFit]) -> dict | None:
    """The fitted model at the reference temperature over the epochs' span (days, mm, sigma), steps kept sharp."""
    if fit.predictor is None or not fit.epoch_days.size:
        return None
    t0, t1 = float(fit.epoch_days.min()), float(fit.epoch_days.max())
    steps = [e.t_days for e in events if math.isfinite(e.t_days) and math.isfinite(e.step_mm)]
    days = np.unique(np.round(np.concatenate([np.linspace(t0, t1, 300), [x - 0.001 for x in steps], steps]), 3))
    days = days[(days >= t0) & (days <= t1)]
    v, s = fit.predict(days)
    return {"days": [_num(x, 3) for x in days], "mm": [_num(x) for x in v], "sigma_mm": [_num(x) for x in s]}


def _target_json(rid: str, fit: TargetFit, t: np.ndarray, origin: int, horizon: float, lim: Limit | None,
                 long_term_factor: float | None) -> dict:
    return {"reflector": rid, "epochs": fit.n_epochs, "thermal_mm_per_degC": _num(fit.thermal_mm_per_degC, 5),
            "thermal_sigma": _num(fit.thermal_sigma, 5), "thermal_p_value": _num(fit.thermal_p_value, 6),
            "thermal_significant": bool(math.isfinite(fit.thermal_p_value) and fit.thermal_p_value < 0.05),
            "temperature_window_h": fit.temperature_window_h, "temperature_lag_h": fit.temperature_lag_h,
            "reference_temperature_degC": _num(fit.reference_temperature_degC, 2),
            "events": [_event_json(e, long_term_factor) for e in fit.events],
            "prediction_offset_mm": None, "prediction_residual_rms_mm": None,
            "trend_mm_per_year": _num(fit.trend_mm_per_year), "trend_sigma": _num(fit.trend_sigma),
            "seasonal_amplitude_mm": _num(fit.seasonal_amplitude_mm), "creep_d_days": fit.creep_d_days,
            "creep_law": fit.creep_law, "sigma_scale": _num(fit.scale, 3), "rms_residual_mm": _num(fit.rms_residual_mm),
            "measured_mm": [_num(v) for v in fit.measured_mm],
            "measured_sigma_mm": [_num(v) for v in fit.measured_sigma_mm],
            "corrected_mm": [_num(v) for v in fit.corrected_mm],
            "corrected_sigma_mm": [_num(v) for v in fit.corrected_sigma_mm],
            "temperature_at_epochs_degC": [_num(v, 2) for v in fit.temperature_at_epochs],
            "epoch_days": [_num(v, 3) for v in fit.epoch_days],
            "model_curve": _model_curve(fit, list(fit.events)),
            "projection": _projection_json(fit, t, origin, horizon, lim), "notes": list(fit.notes)}


def write_analysis(c: Campaign, out_dir: str | os.PathLike, **kw) -> tuple[dict, list[Path]]:
    """``analysis.json`` and one figure per target in ``out_dir``."""
    doc = analyse_campaign(c, **kw)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [write_atomic(out / "analysis.json", json.dumps(doc, indent=1))]
    for t in doc["targets"]:
        paths.append(save_figure(target_figure(doc, t), out / f"analysis-{t['reflector']}.png"))
    return doc, paths

"""The analysis figure of one target: the data, the fitted model, the temperature-corrected series and the events.

Everything on a date axis (with the concrete's age on top when a casting date is set), the colours of
:data:`projects.series.context.COLOURS`, and the legend outside the data.
"""
from __future__ import annotations

import datetime as dt
from typing import Any

import matplotlib
import matplotlib.dates as mdates
import matplotlib.transforms as mtransforms
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from projects.series.context import COLOURS


def _array(values: list | None) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in (values or [])], dtype=float)


def _dates(origin: dt.datetime, days: np.ndarray) -> list[dt.datetime]:
    return [origin + dt.timedelta(days=float(d)) for d in days]


def target_figure(doc: dict, target: dict, *, figsize: tuple[float, float] = (9.0, 4.8)) -> Any:
    """One target's analysis figure (a matplotlib Figure, no GUI toolkit), legend below the plot."""
    matplotlib.use("Agg", force=False)

    fig = Figure(figsize=figsize, dpi=110, layout="constrained")
    draw_target(fig.add_subplot(111), doc, target, legend="below")
    return fig


def draw_target(ax: Any, doc: dict, target: dict, *, legend: str = "below") -> None:
    """Draw one target's analysis on a matplotlib Axes (the file export, the report and the application share it).

    Measured displacements (grey, ±2σ), the temperature-corrected series (blue, ±2σ, when there is a thermal
    term), the fitted model at the reference temperature (black, its ±2σ band shaded) and the events
    (dashed, numbered above the axes), and the design prediction as aligned (dashed teal, when one is imported).
    ``legend`` is ``below`` (under the axes) or ``none``.
    """
    origin = dt.datetime.fromisoformat(doc["time_origin"])
    t = _array(target["epoch_days"])
    thermal = target["thermal_mm_per_degC"] is not None
    handles = []
    meas, meas_s = _array(target.get("measured_mm")), _array(target.get("measured_sigma_mm"))
    if meas.size == t.size and t.size:
        handles.append(ax.errorbar(_dates(origin, t), meas, yerr=2 * meas_s, fmt="o", ms=2.5, lw=0.7, capsize=1.5,
                                   color=COLOURS["measured"], mfc="white", zorder=2,
                                   label="measured (±2σ)"))
    corr, sig = _array(target["corrected_mm"]), _array(target["corrected_sigma_mm"])
    if thermal and corr.size == t.size and t.size:
        ref = target.get("reference_temperature_degC")
        handles.append(ax.errorbar(_dates(origin, t), corr, yerr=2 * sig, fmt="o", ms=3, lw=0.8, capsize=1.5,
                                   color=COLOURS["corrected"], zorder=3,
                                   label="temperature-corrected" + (f" to {ref:.1f} °C" if ref is not None else "")
                                         + " (±2σ)"))
    curve = target.get("model_curve")
    if curve and curve["days"]:
        cd, cv, cs = _array(curve["days"]), _array(curve["mm"]), _array(curve["sigma_mm"])
        when = _dates(origin, cd)
        ax.fill_between(when, cv - 2 * cs, cv + 2 * cs, color=COLOURS["model"], alpha=0.12, lw=0, zorder=1)
        handles.append(ax.plot(when, cv, color=COLOURS["model"], lw=1.1, zorder=4,
                               label="fitted model" + (" at that temperature" if thermal else "") + " (band ±2σ)")[0])
    pred = target.get("prediction_curve")
    if pred and pred["days"]:  # the design prediction, aligned as the analysis table's offset says
        handles.append(ax.plot(_dates(origin, _array(pred["days"])), _array(pred["mm"]), color=COLOURS["series"],
                               lw=1.0, ls=(0, (4, 2)), zorder=3,
                               label=f"design prediction, aligned ({target.get('prediction_alignment', '')}: "
                                     f"offset {target.get('prediction_offset_mm') or 0:+.1f} mm)")[0])
    top = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)

    for k, e in enumerate(doc["events"], start=1):
        day = dt.datetime.fromisoformat(e["date"])
        if day.tzinfo is None:
            day = day.replace(tzinfo=origin.tzinfo)
        ax.axvline(day, color=COLOURS["event"], lw=0.8, ls="--", zorder=1)
        ax.text(day, 1.01, str(k), transform=top, ha="center", va="bottom", fontsize=7, color=COLOURS["event"],
                fontweight="bold", clip_on=False)
        handles.append(Line2D([], [], color=COLOURS["event"], ls="--", lw=0.8,
                              label=f"{k}  {e['label']} ({e['date'][:10]})"))
    ax.set_ylabel("vertical displacement [mm, positive up]")
    ax.grid(alpha=0.3)
    ax.set_title(_title(target), fontsize=9, pad=14)
    casting = doc.get("casting_date")
    if casting:
        c0 = mdates.date2num(dt.datetime.fromisoformat(casting[:10]))
        sec = ax.secondary_xaxis("top", functions=(lambda x: x - c0, lambda a: a + c0))
        sec.set_xlabel(f"concrete age [days since casting on {casting[:10]}]", fontsize=7)
        sec.tick_params(labelsize=7)
    ax.figure.autofmt_xdate()
    if legend == "below" and handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, fontsize=7, frameon=False)


def _title(target: dict) -> str:
    """``M3: thermal 0.11 ± 0.01 mm/°C, trend …`` rounded to what the numbers mean."""
    title = f"{target['reflector']}"
    b = target["thermal_mm_per_degC"]
    parts = []
    if b is not None:
        parts.append(f"thermal {b:+.2f} ± {target['thermal_sigma']:.2f} mm/°C")
    if target["trend_mm_per_year"] is not None:
        parts.append(f"trend {target['trend_mm_per_year']:+.1f} ± {target['trend_sigma']:.1f} mm/year")
    return title + (": " + ", ".join(parts) if parts else "")


def along_figure(target: dict, *, figsize: tuple[float, float] = (3.6, 2.4)) -> Any:
    """A target's along-span movement against the temperature at each scan, ±2σ bars, with its fitted line."""
    pts = np.array(target.get("along_points") or [], dtype=np.float64).reshape(-1, 3)
    fig = Figure(figsize=figsize, dpi=110, layout="constrained")
    ax = fig.subplots()
    ax.errorbar(pts[:, 0], pts[:, 1], yerr=2 * pts[:, 2], fmt="o", ms=3, capsize=2, lw=0.8, color="#1f77b4")
    k = target.get("along_mm_per_degC")
    if k is not None and len(pts):
        w = 1.0 / np.maximum(pts[:, 2], 1e-6) ** 2
        t0, a0 = float(w @ pts[:, 0] / w.sum()), float(w @ pts[:, 1] / w.sum())
        x = np.array([pts[:, 0].min(), pts[:, 0].max()])
        ax.plot(x, a0 + k * (x - t0), color="#d62728", lw=1, label=f"{k:+.3f} mm/°C")
        ax.legend(fontsize=6, frameon=False)
    ax.set_xlabel("temperature at the scan [°C]", fontsize=7)
    ax.set_ylabel("along the span [mm] (±2σ)", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.grid(alpha=0.3)
    ax.set_title(f"{target['reflector']}: movement along the span", fontsize=7)
    return fig

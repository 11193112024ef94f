"""The analysis figure of one target: measured and temperature-corrected histories, events, temperature."""
from __future__ import annotations

import numpy as np


def target_figure(doc: dict, target: dict):
    """One target's analysis figure: measurements, the fitted model and its parts, events, the projection."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4.8), dpi=110)
    draw_target(fig.add_subplot(111), doc, target)
    fig.tight_layout()
    return fig


def draw_target(ax, doc: dict, target: dict) -> None:
    """Draw one target's analysis on a matplotlib Axes (the file export and the application share it)."""
    t = np.array([v if v is not None else np.nan for v in target["epoch_days"]], dtype=float)
    age_shift = None  # with a casting date the time axis is the concrete's age
    ages = target.get("concrete_age_days")
    if ages and len(ages) == t.size and ages[0] is not None:
        age_shift = float(ages[0]) - float(t[0])
        t = t + age_shift
    corr = np.array([v if v is not None else np.nan for v in target["corrected_mm"]], dtype=float)
    sig = np.array([v if v is not None else np.nan for v in target["corrected_sigma_mm"]], dtype=float)
    if corr.size == t.size and t.size:
        label = "temperature-corrected" if target["thermal_mm_per_degC"] is not None else "measured"
        ax.errorbar(t, corr, yerr=2 * sig, fmt="o", ms=3, lw=0.8, capsize=2, label=f"{label} (±2σ)")
    import datetime as dt

    origin = dt.datetime.fromisoformat(doc["time_origin"])
    for e in doc["events"]:
        day = (dt.datetime.fromisoformat(e["date"]) - origin).total_seconds() / 86400 + (age_shift or 0.0)
        ax.axvline(day, color="tab:red", lw=0.8, ls="--")
        ax.annotate(e["label"], (day, 1), xycoords=("data", "axes fraction"), rotation=90, va="top", ha="right",
                    fontsize=7, color="tab:red")
    temps = [v for v in target["temperature_at_epochs_degC"]]
    if temps and any(v is not None for v in temps) and len(temps) == t.size:
        ax2 = ax.twinx()
        ax2.plot(t, [np.nan if v is None else v for v in temps], color="tab:orange", lw=0.8, alpha=0.7)
        ax2.set_ylabel("temperature at the epochs (°C)", color="tab:orange")
    ax.set_xlabel(f"concrete age (days since casting on {doc['casting_date'][:10]})" if age_shift is not None
                  else f"days from the baseline ({doc['baseline']})")
    ax.set_ylabel("vertical displacement (mm, positive up)")
    b = target["thermal_mm_per_degC"]
    title = f"{target['reflector']}"
    if b is not None:
        title += f": {b:+.3f} ± {target['thermal_sigma']:.3f} mm/°C"
    if target["trend_mm_per_year"] is not None:
        title += f", trend {target['trend_mm_per_year']:+.2f} mm/year"
    ax.set_title(title)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower left", fontsize=8)

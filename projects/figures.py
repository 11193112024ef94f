"""Campaign figures (matplotlib, no GUI toolkit)."""
from __future__ import annotations

import datetime as dt
from collections import defaultdict

import numpy as np


def displacement_history_figure(rows: list[dict], *, title: str = "Vertical displacement history"):
    """Displacement of every measurement target over time with 2-sigma error bars and limit lines."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 5), dpi=110, layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    series = defaultdict(list)
    for r in rows:
        if r["displacement_mm"] is None:
            continue
        series[r["reflector"]].append((dt.datetime.fromisoformat(r["datetime"]), r["displacement_mm"],
                                       r["sigma_mm"] or 0.0, r))
    for rid in sorted(series):
        pts = series[rid]
        t = [p[0] for p in pts]
        ax.errorbar(t, [p[1] for p in pts], yerr=[2 * p[2] for p in pts], marker="o", ms=3, lw=1, capsize=2,
                    label=rid)
    lims = {(r["warning_mm"], r["alarm_mm"]) for r in rows if r.get("alarm_mm")}
    for w, a in lims:
        for v, style, name in ((w, ":", "warning"), (a, "--", "alarm")):
            if v:
                ax.axhline(-v, color="tab:orange" if name == "warning" else "tab:red", ls=style, lw=1,
                           label=f"{name} -{v:.1f} mm")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_ylabel("displacement [mm] (positive up, ±2σ)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if series:
        ax.legend(ncol=4, fontsize=8, loc="lower left")
    fig.autofmt_xdate()
    return fig

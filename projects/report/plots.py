"""Report figures (matplotlib Figures, no GUI toolkit): layout, per-target histories, epoch maps."""
from __future__ import annotations

import datetime as dt
from collections import defaultdict
from typing import Optional, Sequence

import numpy as np

GROUP_STYLE = {"reference": ("s", "tab:blue"), "measurement": ("o", "tab:green")}


def layout_figure(reflectors: Sequence[dict], states: Sequence = (), *, span_m: Optional[float] = None):
    """Plan (x, y) and elevation (x, z) of the reflector layout, flagged targets in red."""
    from matplotlib.figure import Figure

    trouble = {s.reflector for s in states if s.remarks and not (len(s.remarks) == 1 and
                                                                  s.remarks[0].startswith("replaces"))}
    fig = Figure(figsize=(7.0, 4.6), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    for ax, (j, name) in zip(axes, ((1, "y [m]"), (2, "z [m]"))):
        for grp, (marker, colour) in GROUP_STYLE.items():
            pts = [r for r in reflectors if r["grp"] == grp]
            if not pts:
                continue
            ax.scatter([r["x"] for r in pts], [(r["y"], r["z"])[j - 1] for r in pts], marker=marker, c=colour,
                       s=28, label=f"{grp} ({len(pts)})", zorder=3)
        for r in reflectors:
            colour = "tab:red" if r["id"] in trouble else "0.2"
            ax.annotate(r["id"], (r["x"], (r["y"], r["z"])[j - 1]), xytext=(4, 4), textcoords="offset points",
                        fontsize=7, color=colour)
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.margins(0.12)
    axes[0].set_title("Plan" + (f" (span {span_m:g} m)" if span_m else ""), fontsize=9)
    axes[1].set_title("Elevation", fontsize=9)
    axes[1].set_xlabel("x [m] (layout frame)")
    axes[0].legend(fontsize=7, loc="best")
    return fig


def history_grid_figure(rows: Sequence[dict], *, targets: Optional[Sequence[str]] = None, max_points: int = 2000,
                        context=None):
    """One panel per measurement target: displacement with ±2σ bars, warning and alarm lines, and
    (``context``, a :class:`projects.context.PlotContext`) the events and an environment series.

    Series longer than ``max_points`` are thinned for drawing only.
    """
    from matplotlib.figure import Figure

    series = defaultdict(list)
    lims = {}
    for r in rows:
        lims.setdefault(r["reflector"], (r.get("warning_mm"), r.get("alarm_mm")))
        if r["displacement_mm"] is None:
            continue
        series[r["reflector"]].append((dt.datetime.fromisoformat(r["datetime"]), r["displacement_mm"],
                                       r["sigma_mm"] or 0.0, bool(r["flags"])))
    names = list(targets) if targets is not None else sorted(lims)
    n = max(len(names), 1)
    fig = Figure(figsize=(7.0, min(1.55 * n + 0.6, 9.4)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True))
    for ax, rid in zip(axes, names):
        pts = series.get(rid, [])
        if len(pts) > max_points:
            pts = pts[:: int(np.ceil(len(pts) / max_points))]
        if pts:
            t = [p[0] for p in pts]
            u = np.array([p[1] for p in pts])
            s2 = 2 * np.array([p[2] for p in pts])
            ax.errorbar(t, u, yerr=s2, fmt="o-", ms=2.5, lw=0.9, capsize=1.5, color="tab:blue", ecolor="0.45")
            bad = [k for k, p in enumerate(pts) if p[3]]
            if bad:
                ax.plot([t[k] for k in bad], u[bad], "o", mfc="none", mec="tab:orange", ms=6, label="flagged")
                ax.legend(fontsize=6, loc="lower left")
        w, a = lims.get(rid, (None, None))
        lo, hi = ax.get_ylim() if pts else (-1.0, 1.0)
        reach = max(abs(lo), abs(hi), 1.0)
        off_scale = []
        for v, style, colour, name in ((w, ":", "tab:orange", "warning"), (a, "--", "tab:red", "alarm")):
            if not v:
                continue
            if v <= 2.0 * reach:  # near the data: draw it and keep it in view
                ax.axhline(-v, color=colour, ls=style, lw=0.9)
                lo = min(lo, -1.08 * v)
            else:  # far below the data: a line would squash the history flat
                off_scale.append(f"{name} −{v:.1f} mm")
        ax.set_ylim(lo, hi)
        if off_scale:
            ax.text(0.99, 0.04, "below the plot: " + ", ".join(off_scale), transform=ax.transAxes, ha="right",
                    va="bottom", fontsize=6, color="tab:red")
        ax.axhline(0, color="0.6", lw=0.6)
        if context is not None and pts:
            from projects.context import draw_context

            draw_context(ax, context, label_events=ax is axes[0])
        ax.set_ylabel(f"{rid}\n[mm]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0].set_title("Vertical displacement (positive up, bars ±2σ; dotted: warning, dashed: alarm)", fontsize=8)
    fig.autofmt_xdate()
    return fig


def epoch_map_figure(preview, plan: Optional[dict], *, title: str):
    """The epoch's reflectance map with detections, identified targets and the planned windows."""
    from lidar.figures import reflectance_map_figure
    from lidar.plan import RoiPlan
    from lidar.reflectance_map import reduce_map

    rois = [RoiPlan.from_json(r) for r in plan["rois"]] if plan else None
    fig = reflectance_map_figure(reduce_map(preview.reflectance_map, max_cells=300_000),
                                 detections=preview.detections, identification=preview.identification, rois=rois,
                                 title=title, figsize=(7.0, 3.1), fixed_layout=True)
    for ax in fig.axes:
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_size(8)
        ax.yaxis.label.set_size(8)
        ax.title.set_size(9)
    return fig

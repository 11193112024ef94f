"""Report figures (matplotlib Figures, no GUI toolkit): layout, per-target histories, epoch maps."""
from __future__ import annotations

from typing import Mapping, Optional, Sequence

import numpy as np

from projects.store.history import DisplacementHistory
from projects.store.records import Reflector

GROUP_STYLE = {"reference": ("s", "tab:blue"), "measurement": ("o", "tab:green")}


def layout_figure(reflectors: Sequence[Reflector], states: Sequence = (), *, span_m: Optional[float] = None):
    """Plan (x, y) and elevation (x, z) of the reflector layout, flagged targets in red."""
    from matplotlib.figure import Figure

    trouble = {s.reflector for s in states if s.remarks and not (len(s.remarks) == 1 and
                                                                  s.remarks[0].startswith("replaces"))}
    fig = Figure(figsize=(7.0, 4.6), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    for ax, (j, name) in zip(axes, ((1, "y [m]"), (2, "z [m]"))):
        for grp, (marker, colour) in GROUP_STYLE.items():
            pts = [r for r in reflectors if r.group == grp]
            if not pts:
                continue
            ax.scatter([r.xyz_layout[0] for r in pts], [r.xyz_layout[j] for r in pts], marker=marker, c=colour,
                       s=28, label=f"{grp} ({len(pts)})", zorder=3)
        for r in reflectors:
            colour = "tab:red" if r.id in trouble else "0.2"
            ax.annotate(r.id, (r.xyz_layout[0], r.xyz_layout[j]), xytext=(4, 4), textcoords="offset points",
                        fontsize=7, color=colour)
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.margins(0.12)
    axes[0].set_title("Plan" + (f" (span {span_m:g} m)" if span_m else ""), fontsize=9)
    axes[1].set_title("Elevation", fontsize=9)
    axes[1].set_xlabel("x [m] (layout frame)")
    axes[0].legend(fontsize=7, loc="best")
    return fig


def history_grid_figure(histories: Mapping[str, DisplacementHistory], *, targets: Optional[Sequence[str]] = None, max_points: int = 2000,
                        context=None):
    """One panel per measurement target: displacement with ±2σ bars, warning and alarm lines.

    Also (``context``, a :class:`projects.context.PlotContext`) the events and an environment series.

    ``histories`` as :func:`projects.history.histories` gives them. Series longer than ``max_points`` are
    thinned for drawing only.
    """
    from matplotlib.figure import Figure

    names = list(targets) if targets is not None else sorted(histories)
    n = max(len(names), 1)
    fig = Figure(figsize=(7.0, min(1.55 * n + 0.6, 9.4)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True))
    for ax, rid in zip(axes, names):
        h = histories.get(rid)
        pts = h.measured().thinned(max_points) if h is not None else None
        if pts:
            t = list(pts.times)
            u = pts.displacement_mm
            ax.errorbar(t, u, yerr=2 * pts.sigma_mm, fmt="o-", ms=2.5, lw=0.9, capsize=1.5, color="tab:blue",
                        ecolor="0.45")
            bad = np.flatnonzero(pts.flagged)
            if bad.size:
                ax.plot([t[k] for k in bad], u[bad], "o", mfc="none", mec="tab:orange", ms=6, label="flagged")
                ax.legend(fontsize=6, loc="lower left")
        lim = h.limit if h is not None else None
        w, a = (lim.warning_mm, lim.alarm_mm) if lim is not None else (None, None)
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
            from projects.series.context import draw_context

            draw_context(ax, context, label_events=ax is axes[0])
        ax.set_ylabel(f"{rid}\n[mm]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0].set_title("Vertical displacement (positive up, bars ±2σ; dotted: warning, dashed: alarm)", fontsize=8)
    fig.autofmt_xdate()
    return fig


def epoch_map_figure(preview, plan, *, title: str):
    """The epoch's reflectance map with detections, identified targets and the planned windows.

    (``plan`` a :class:`lidar.plan.ScanPlan` or None).
    """
    from lidar.figures import reflectance_map_figure
    from lidar.reflectance_map import reduce_map

    rois = list(plan.rois) if plan is not None else None
    fig = reflectance_map_figure(reduce_map(preview.reflectance_map, max_cells=300_000),
                                 detections=preview.detections, identification=preview.identification, rois=rois,
                                 title=title, figsize=(7.0, 3.1), fixed_layout=True)
    for ax in fig.axes:
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_size(8)
        ax.yaxis.label.set_size(8)
        ax.title.set_size(9)
    return fig

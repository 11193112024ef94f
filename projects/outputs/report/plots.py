"""Report figures (matplotlib Figures, no GUI toolkit): layout, per-target histories, epoch maps."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from lidar.figures import reflectance_map_figure
from lidar.reflectance_map import reduce_map
from projects.outputs.figures import LIMIT_STYLES, figure_legend, limit_of
from projects.series.context import COLOURS, PlotContext, draw_context
from projects.store.history import DisplacementHistory
from projects.store.limits import Limit
from projects.store.records import Reflector

GROUP_STYLE = {"reference": ("s", "tab:blue"), "measurement": ("o", "tab:green")}


def layout_figure(reflectors: Sequence[Reflector], states: Sequence = (), *, span_m: float | None = None) -> Any:
    """Plan (x, y) and elevation (x, z) of the reflector layout, flagged targets in red; the legend above."""
    trouble = {s.reflector for s in states if s.remarks and not (len(s.remarks) == 1 and
                                                                  s.remarks[0].startswith("replaces"))}
    fig = Figure(figsize=(7.0, 4.6), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    handles = []
    for ax, (j, name) in zip(axes, ((1, "y [m]"), (2, "z [m]")), strict=False):
        for grp, (marker, colour) in GROUP_STYLE.items():
            pts = [r for r in reflectors if r.group == grp]
            if not pts:
                continue
            sc = ax.scatter([r.xyz_layout[0] for r in pts], [r.xyz_layout[j] for r in pts], marker=marker, c=colour,
                            s=28, label=f"{grp} targets ({len(pts)})", zorder=3)
            if ax is axes[0]:
                handles.append(sc)
        for r in reflectors:
            colour = "tab:red" if r.id in trouble else "0.2"
            ax.annotate(r.id, (r.xyz_layout[0], r.xyz_layout[j]), xytext=(4, 4), textcoords="offset points",
                        fontsize=7, color=colour)
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
        ax.margins(0.12)
    if trouble:
        handles.append(Line2D([], [], ls="", marker="$M$", color="tab:red", label="red label: target with a remark"))
    axes[0].set_title("Plan" + (f" (span {span_m:g} m)" if span_m else ""), fontsize=9)
    axes[1].set_title("Elevation", fontsize=9)
    axes[1].set_xlabel("x [m] (layout frame)")
    figure_legend(fig, handles, fontsize=7)
    return fig


def _limit_lines(ax: Any, lim: Limit | None, lo: float, hi: float, drawn: set[tuple[str, float]]
                 ) -> tuple[float, list[str]]:
    """Draw the limits near the data (keeping them in view, added to ``drawn``); name the ones far below it.

    Returns the new lower y limit and the names of the limits off the scale.
    """
    reach = max(abs(lo), abs(hi), 1.0)
    off_scale = []
    for key, style, name in LIMIT_STYLES:
        v = getattr(lim, f"{key}_mm") if lim is not None else None
        if not v:
            continue
        if v <= 2.0 * reach:  # near the data: draw it and keep it in view
            ax.axhline(-v, color=COLOURS[key], ls=style, lw=0.9)
            drawn.add((key, v))
            lo = min(lo, -1.08 * v)
        else:  # far below the data: a line would squash the history flat
            off_scale.append(f"{name} −{v:.1f} mm")
    return lo, off_scale


def history_grid_figure(histories: Mapping[str, DisplacementHistory], *, targets: Sequence[str] | None = None,
                        max_points: int = 2000, context: PlotContext | None = None) -> Any:
    """One panel per measurement target: displacement with ±2σ bars, warning and alarm lines.

    Also (``context``, a :class:`projects.series.context.PlotContext`) the events and an environment series.
    One legend above the panels says which colour is which; limits far below the data are named above
    their panel, outside the data. ``histories`` as :func:`projects.store.history.histories` gives them.
    Series longer than ``max_points`` are thinned for drawing only.
    """
    names = list(targets) if targets is not None else sorted(histories)
    n = max(len(names), 1)
    fig = Figure(figsize=(7.0, min(1.55 * n + 1.0, 9.4)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(n, 1, sharex=True))
    handles = [Line2D([], [], color=COLOURS["data"], marker="o", ms=3, lw=0.9, label="displacement, positive up (bars ±2σ)")]
    any_flagged = False
    drawn: set[tuple[str, float]] = set()
    extra: list = []
    for ax, rid in zip(axes, names, strict=False):
        h = histories.get(rid)
        pts = h.measured().thinned(max_points) if h is not None else None
        if pts:
            t = list(pts.times)
            u = pts.displacement_mm
            ax.errorbar(t, u, yerr=2 * pts.sigma_mm, fmt="o-", ms=2.5, lw=0.9, capsize=1.5, color=COLOURS["data"],
                        ecolor="0.45", zorder=3)
            bad = np.flatnonzero(pts.flagged)
            if bad.size:
                any_flagged = True
                ax.plot([t[k] for k in bad], u[bad], "o", mfc="none", mec=COLOURS["flagged"], mew=1.0, ms=6.5, zorder=4)
        lo, hi = ax.get_ylim() if pts else (-1.0, 1.0)
        lo, off_scale = _limit_lines(ax, limit_of(h), lo, hi, drawn)
        ax.set_ylim(lo, hi)
        if off_scale:
            ax.set_title("below the plot: " + ", ".join(off_scale), loc="right", fontsize=6, color="0.3", pad=2)
        ax.axhline(0, color="0.6", lw=0.6)
        if context is not None and pts:
            got = draw_context(ax, context, label_events=ax is axes[0])
            extra = extra or got
        ax.set_ylabel(f"{rid}\n[mm]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    if any_flagged:
        handles.append(Line2D([], [], ls="", marker="o", mfc="none", mec=COLOURS["flagged"], ms=6,
                              label="flagged (see the epoch pages)"))
    for key, style, name in LIMIT_STYLES:  # only the limits drawn: the others are named above their panel
        handles += [Line2D([], [], color=COLOURS[key], ls=style, lw=1.0, label=f"{name} −{v:.1f} mm")
                    for k, v in sorted(drawn) if k == key]
    handles += extra
    figure_legend(fig, handles, ncol=3, fontsize=6.5)
    fig.autofmt_xdate()
    return fig


def epoch_map_figure(preview: Any, plan: Any, *, title: str) -> Any:
    """The epoch's reflectance map with detections, identified targets and the planned windows.

    (``plan`` a :class:`lidar.plan.ScanPlan` or None).
    """
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

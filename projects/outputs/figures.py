"""Campaign figures (matplotlib, no GUI toolkit), and the legend and limit helpers the report's figures share."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, cast

from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from projects.series.context import COLOURS, PlotContext, draw_context
from projects.store.history import DisplacementHistory
from projects.store.limits import Limit

#: Colours of the targets on a plot of several: none of them is a limit's, an event's or a series' colour.
TARGET_COLOURS = ("#1f77b4", "#2ca02c", "#8c564b", "#7f7f7f", "#bcbd22", "#000080", "#e377c2", "#17a768",
                  "#5a5a00", "#4a6fa5")
#: How each limit is drawn: (key in COLOURS, line style, name).
LIMIT_STYLES = (("warning", ":", "warning"), ("alarm", "--", "alarm"))


def limit_of(h: DisplacementHistory | None) -> Limit | None:
    """The limit that applies to a history (None without one)."""
    return None if h is None else cast(Limit | None, h.limit)


def limit_handles(limits: Sequence[Limit]) -> list:
    """Legend entries of the distinct warning and alarm levels, e.g. ``warning −16.8 mm``."""
    out = []
    for key, style, name in LIMIT_STYLES:
        for v in sorted({getattr(lim, f"{key}_mm") for lim in limits if getattr(lim, f"{key}_mm")}):
            out.append(Line2D([], [], color=COLOURS[key], ls=style, lw=1.0, label=f"{name} −{v:.1f} mm"))
    return out


def figure_legend(fig: Any, handles: Sequence, *, ncol: int = 4, fontsize: float = 7) -> None:
    """One legend for the whole figure, above its axes (never over the data); needs constrained layout."""
    if handles:
        fig.legend(handles=list(handles), loc="outside upper center", ncol=min(ncol, len(handles)), fontsize=fontsize,
                   frameon=False, handlelength=2.2, columnspacing=1.4)


def displacement_history_figure(histories: Mapping[str, DisplacementHistory], *,
                                title: str = "Vertical displacement history", context: PlotContext | None = None,
                                series: bool = True, figsize: tuple[float, float] = (11.0, 5.0)) -> Any:
    """Displacement of every measurement target over time with 2-sigma error bars and limit lines.

    Also the events and (``series``) the environment series of ``context``, a
    :class:`projects.series.context.PlotContext`. The legend sits above the plot, never over the data.
    ``histories`` as :func:`projects.store.history.histories` gives them (reflector -> history).
    """
    fig = Figure(figsize=figsize, dpi=110, layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    handles = []
    for k, rid in enumerate(sorted(histories)):
        h = histories[rid].measured()
        if len(h):
            handles.append(ax.errorbar(cast(Any, list(h.times)), h.displacement_mm, yerr=2 * h.sigma_mm, marker="o", ms=3, lw=1,
                                       capsize=2, label=rid, color=TARGET_COLOURS[k % len(TARGET_COLOURS)]))
    lims = [lim for lim in (limit_of(h) for h in histories.values()) if lim is not None and lim.alarm_mm]
    for key, style, _ in LIMIT_STYLES:
        for v in sorted({getattr(lim, f"{key}_mm") for lim in lims if getattr(lim, f"{key}_mm")}):
            ax.axhline(-v, color=COLOURS[key], ls=style, lw=1)
    handles += limit_handles(lims)
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_ylabel("displacement [mm] (positive up, ±2σ)")
    ax.set_title(title, pad=12)  # room for the event numbers above the axes
    ax.grid(alpha=0.3)
    if handles:
        handles += draw_context(ax, context, series=series)
    figure_legend(fig, handles, ncol=max(2, int(figsize[0] / 2.2)))
    fig.autofmt_xdate()
    return fig

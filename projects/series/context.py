"""What every time plot can show beside the displacements: events and an environment series.

``plot_context(c)`` collects them from a campaign; ``draw_context(ax, ctx)`` draws them on a matplotlib
Axes with datetime x values (events as dashed lines, the series on a second y axis as daily means).
"""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from typing import Optional

import numpy as np


@dataclass(frozen=True)
class PlotContext:
    """What explains a displacement plot: the events (date, label) and one environment series (daily means)."""

    events: tuple[tuple[dt.datetime, str], ...] = ()
    series_name: Optional[str] = None
    series_unit: str = ""
    series_days: tuple = ()  # datetimes of daily means
    series_values: np.ndarray = field(default_factory=lambda: np.zeros(0))


def plot_context(c, *, kind_preference=("structure-temperature", "temperature")) -> PlotContext:
    """Events and the first series of the preferred kinds (daily means), from an open campaign."""
    from projects.series.environment import events, load_env

    evs = tuple((e.when, e.label) for e in events(c))
    for kind in kind_preference:
        series = load_env(c, kind=kind)
        if series:
            s = series[0]
            day = (s.time_ns // (86_400 * 10**9)).astype(np.int64)
            ok = np.isfinite(s.value)
            days, inv = np.unique(day[ok], return_inverse=True)
            means = np.bincount(inv, s.value[ok]) / np.bincount(inv)
            when = tuple(dt.datetime.fromtimestamp(int(d) * 86400 + 43200, dt.timezone.utc) for d in days)
            return PlotContext(evs, f"{s.name} ({s.kind})", s.unit, when, means)
    return PlotContext(evs)


def draw_context(ax, ctx: Optional[PlotContext], *, label_events: bool = True, series: bool = True) -> None:
    """Draw the events (dashed lines) and the environment series (on a twin axis) behind a time plot."""
    if ctx is None:
        return
    lo, hi = ax.get_xlim()
    import matplotlib.dates as mdates

    for when, label in ctx.events:
        x = mdates.date2num(when)
        ax.axvline(when, color="tab:purple", ls="--", lw=0.8, alpha=0.8)
        if label_events:
            ax.annotate(label, (x, 1.0), xycoords=("data", "axes fraction"), rotation=90, va="top", ha="right",
                        fontsize=6, color="tab:purple")
    if series and len(ctx.series_days):
        ax2 = ax.twinx()
        ax2.plot(ctx.series_days, ctx.series_values, color="tab:orange", lw=0.7, alpha=0.6)
        ax2.set_ylabel(ctx.series_unit, color="tab:orange", fontsize=7)
        ax2.tick_params(labelsize=6, colors="tab:orange")
    ax.set_xlim(lo, hi)

"""What every time plot can show beside the displacements: events and an environment series.

``plot_context(c)`` collects them from a campaign; ``draw_context(ax, ctx)`` draws them on a matplotlib
Axes with datetime x values: events as dashed lines numbered above the axes, the series on a second y axis
behind the data, as daily means over whole days only (a partial day's mean is biased by the daily swing).
Every time plot uses the colours of :data:`COLOURS`, so a legend means the same everywhere.
"""
from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import matplotlib.dates as mdates
import matplotlib.transforms as mtransforms
import numpy as np
from matplotlib.lines import Line2D

from projects.series.environment import events, load_env

DAY_NS = 86_400 * 10**9
#: A day's mean is drawn only when its valid samples cover at least this share of it (count x typical step).
WHOLE_DAY_COVERAGE = 0.95
#: Series sampled more sparsely than this (hours) are drawn as their samples, not as daily means.
MAX_STEP_FOR_DAILY_MEANS_H = 6.0
#: One colour per meaning on every time plot: data, flagged values, limits, events and the environment series.
COLOURS = {"data": "tab:blue", "flagged": "black", "warning": "#e69f00", "alarm": "#d62728", "event": "#7b3fa0",
           "series": "#009e9e", "corrected": "tab:blue", "measured": "0.55", "model": "black"}


@dataclass(frozen=True)
class PlotContext:
    """What explains a displacement plot: the events (date, label) and one environment series."""

    events: tuple[tuple[dt.datetime, str], ...] = ()
    series_name: str | None = None
    series_unit: str = ""
    series_days: tuple = ()  # datetimes of the plotted values
    series_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    series_statistic: str = "daily means"  # or "samples" for a sparse series

    @property
    def series_label(self) -> str:
        """The series as a legend names it, e.g. ``air-temperature (temperature), daily means [°C]``."""
        return f"{self.series_name}, {self.series_statistic}" + (f" [{self.series_unit}]" if self.series_unit else "")


def whole_day_means(time_ns: np.ndarray, values: np.ndarray, *, coverage: float = WHOLE_DAY_COVERAGE
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Means of the UTC days whose valid samples cover at least ``coverage`` of the day.

    Parameters
    ----------
    time_ns : (n,) int64, sorted UTC times in nanoseconds
    values : (n,) float; NaN is a gap
    coverage : share of the day the samples must cover (their count times the series' median step)

    Returns
    -------
    days : (k,) int64, day numbers (days since 1970-01-01)
    means : (k,) float

    >>> t = np.arange(9, 72) * 3_600 * 10**9  # hourly from 09:00 on day 0 to 23:00 on day 2
    >>> days, means = whole_day_means(t, np.ones(t.size))
    >>> days.tolist()  # day 0 starts at 09:00: not a whole day
    [1, 2]
    """
    ok = np.isfinite(values)
    t, v = np.asarray(time_ns, np.int64)[ok], np.asarray(values, float)[ok]
    if t.size < 2:
        return np.zeros(0, np.int64), np.zeros(0)
    step_ns = float(np.median(np.diff(t)))
    day = t // DAY_NS
    days, inv, counts = np.unique(day, return_inverse=True, return_counts=True)
    means = np.bincount(inv, v) / counts
    whole = counts * step_ns >= coverage * DAY_NS
    return days[whole].astype(np.int64), means[whole]


def series_for_plot(time_ns: np.ndarray, values: np.ndarray) -> tuple[tuple[dt.datetime, ...], np.ndarray, str]:
    """What a time plot draws of a series: (times, values, ``daily means`` or ``samples``).

    Daily means over whole days (at noon UTC) for a series sampled at least every
    :data:`MAX_STEP_FOR_DAILY_MEANS_H` hours; the samples themselves for a sparser one.
    """
    ok = np.isfinite(values)
    t = np.asarray(time_ns, np.int64)[ok]
    step_h = float(np.median(np.diff(t))) / 3.6e12 if t.size > 1 else float("inf")
    if step_h > MAX_STEP_FOR_DAILY_MEANS_H:
        return (tuple(dt.datetime.fromtimestamp(int(x) / 1e9, dt.UTC) for x in t),
                np.asarray(values, float)[ok], "samples")
    days, means = whole_day_means(time_ns, values)
    return tuple(dt.datetime.fromtimestamp(int(d) * 86400 + 43200, dt.UTC) for d in days), means, "daily means"


def plot_context(c: Any, *, kind_preference: Sequence[str] = ("structure-temperature", "temperature")) -> PlotContext:
    """Events and the first series of the preferred kinds, from an open campaign."""
    evs = tuple((e.when, e.label) for e in events(c))
    for kind in kind_preference:
        series = load_env(c, kind=kind)
        if series:
            s = series[0]
            when, vals, statistic = series_for_plot(s.time_ns, s.value)
            return PlotContext(evs, f"{s.name} ({s.kind})", s.unit, when, vals, statistic)
    return PlotContext(evs)


def event_handles(ctx: PlotContext | None) -> list:
    """Legend entries for the events: a dashed line labelled ``1  label (date)`` for each."""
    if ctx is None:
        return []
    return [Line2D([], [], color=COLOURS["event"], ls="--", lw=0.9,
                   label=f"{k}  {label} ({when.date().isoformat()})")
            for k, (when, label) in enumerate(ctx.events, start=1)]


def series_handle(ctx: PlotContext | None) -> list:
    """The legend entry of the environment series (empty without one)."""
    if ctx is None or not len(ctx.series_days):
        return []
    return [Line2D([], [], color=COLOURS["series"], lw=1.0, label=ctx.series_label)]


def draw_context(ax: Any, ctx: PlotContext | None, *, label_events: bool = True, series: bool = True) -> list:
    """Draw the events and the environment series behind a time plot; returns their legend entries.

    Events are dashed lines, numbered just above the axes when ``label_events`` (the legend entries name
    them); the series goes on a twin y axis drawn behind the data, in its own colour. The x range is kept.
    """
    if ctx is None:
        return []
    lo, hi = ax.get_xlim()
    top = mtransforms.blended_transform_factory(ax.transData, ax.transAxes)
    for k, (when, _) in enumerate(ctx.events, start=1):
        x = mdates.date2num(when)
        ax.axvline(when, color=COLOURS["event"], ls="--", lw=0.8, alpha=0.9, zorder=1)
        if label_events and lo <= x <= hi:
            ax.text(x, 1.01, str(k), transform=top, ha="center", va="bottom", fontsize=6.5, color=COLOURS["event"],
                    fontweight="bold", clip_on=False)
    handles = event_handles(ctx)
    if series and len(ctx.series_days):
        ax2 = ax.twinx()
        ax2.plot(ctx.series_days, ctx.series_values, color=COLOURS["series"], lw=0.8, alpha=0.8)
        ax2.set_ylabel(ctx.series_unit, color=COLOURS["series"], fontsize=7)
        ax2.tick_params(labelsize=6, colors=COLOURS["series"])
        ax.set_zorder(ax2.get_zorder() + 1)  # the displacements in front, the series behind them
        ax.patch.set_visible(False)
        handles += series_handle(ctx)
    ax.set_xlim(lo, hi)
    return handles

"""The time plots read like a professional's: nothing over the data, one colour per meaning, whole days only."""
from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from projects.series.context import COLOURS, PlotContext, series_for_plot, whole_day_means
from projects.store.history import DisplacementHistory
from projects.store.limits import Limit

START = dt.datetime(2026, 1, 5, 9, tzinfo=dt.UTC)
HOUR_NS = 3_600 * 10**9


def _history(rid: str, n: int = 30, *, limit=Limit(16.842105263157897, 21.05263157894737, "kr-rail:0-200"),
             sag: float = -6.0, flagged: int = 7) -> DisplacementHistory:
    times = tuple(START + dt.timedelta(weeks=k) for k in range(n))
    u = np.linspace(0.0, sag, n)
    flags = tuple(("missing",) if k == flagged else () for k in range(n))
    return DisplacementHistory(rid, tuple(t.date().isoformat() for t in times), times, u, np.full(n, 0.1), flags,
                               ((),) * n, (times[0].date().isoformat(),) * n, limit)


def _context() -> PlotContext:
    t = (np.datetime64(START.replace(tzinfo=None), "ns").astype(np.int64) + np.arange(0, 30 * 7 * 24) * HOUR_NS)
    when, vals, stat = series_for_plot(t, 10 + 5 * np.sin(np.arange(t.size) / 500.0))
    return PlotContext(((START + dt.timedelta(days=40), "slab cast"), (START + dt.timedelta(days=120), "ballast")),
                       "air (temperature)", "°C", when, vals, stat)


def _overlaps_data(fig) -> list[str]:
    """Legends and notes (texts that label no data point) whose box reaches into the plotting area of an axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Annotation

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    r = canvas.get_renderer()
    boxes = [(ax, ax.get_window_extent(r)) for ax in fig.axes]
    found = []
    things = [(f"legend {k}", lg) for k, lg in enumerate(fig.legends)]
    for ax in fig.axes:
        if ax.get_legend() is not None:
            things.append((f"legend of {ax.get_ylabel()!r}", ax.get_legend()))
        things += [(f"text {t.get_text()!r}", t) for t in ax.texts
                   if t.get_visible() and t.get_text() and not isinstance(t, Annotation)]
    for name, artist in things:
        b = artist.get_window_extent(r)
        for _ax, a in boxes:
            if b.x0 < a.x1 - 1 and b.x1 > a.x0 + 1 and b.y0 < a.y1 - 1 and b.y1 > a.y0 + 1:
                found.append(name)
    return found


def test_whole_days_only_so_the_daily_mean_does_not_dip_at_the_ends():
    t = np.arange(9, 24 * 5 + 15) * HOUR_NS  # from 09:00 on day 0 to 14:00 on day 5
    hour = (t // HOUR_NS) % 24
    swing = 10 + 4 * np.sin(2 * np.pi * (hour - 9) / 24)  # the same day every day
    days, means = whole_day_means(t, swing)
    assert days.tolist() == [1, 2, 3, 4] and means == pytest.approx(10.0)
    gappy = swing.copy()
    gappy[(t >= 2 * 24 * HOUR_NS) & (t < 2 * 24 * HOUR_NS + 6 * HOUR_NS)] = np.nan  # six hours missing on day 2
    assert whole_day_means(t, gappy)[0].tolist() == [1, 3, 4]
    when, vals, stat = series_for_plot(t, swing)
    assert stat == "daily means" and len(when) == 4 and when[0].hour == 12
    sparse = np.arange(0, 40) * 12 * HOUR_NS  # twice a day: too sparse for daily means
    when, vals, stat = series_for_plot(sparse, np.ones(sparse.size))
    assert stat == "samples" and len(when) == 40


def test_the_colours_mean_one_thing_each():
    from projects.outputs.figures import TARGET_COLOURS

    meanings = [COLOURS[k] for k in ("data", "flagged", "warning", "alarm", "event", "series")]
    assert len(set(meanings)) == len(meanings)
    assert not set(TARGET_COLOURS) & set(COLOURS[k] for k in ("flagged", "warning", "alarm", "event", "series"))


def test_history_panels_keep_legend_and_notes_off_the_data():
    from matplotlib.colors import to_hex

    from projects.outputs.report.plots import history_grid_figure

    near = _history("M1", sag=-15.0)  # the warning line is drawn in the panel
    far = _history("M2", sag=-3.0)  # the limits are far below: named above the panel
    fig = history_grid_figure({"M1": near, "M2": far}, context=_context())
    assert _overlaps_data(fig) == []
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "warning −16.8 mm" in labels and "flagged (see the epoch pages)" in labels
    assert any(x.startswith("1  slab cast") for x in labels) and any("air (temperature)" in x for x in labels)
    assert not any("21.05" in x or "16.84" in x for x in labels)
    m1, m2 = fig.axes[0], fig.axes[1]
    assert "below the plot: warning −16.8 mm, alarm −21.1 mm" in m2.get_title(loc="right")
    colours = {to_hex(line.get_color()) for ax in fig.axes for line in ax.get_lines()}
    for key in ("warning", "event", "series"):
        assert to_hex(COLOURS[key]) in colours, key
    rings = [ln for ln in m1.get_lines() if ln.get_marker() == "o" and ln.get_markerfacecolor() == "none"]
    assert rings and to_hex(rings[0].get_markeredgecolor()) == to_hex(COLOURS["flagged"])


def test_campaign_and_layout_figures_keep_the_legend_off_the_data():
    from projects.outputs.figures import displacement_history_figure
    from projects.outputs.report.plots import layout_figure
    from projects.store.records import Reflector

    hist = {f"M{k}": _history(f"M{k}", sag=-4.0 - k) for k in range(1, 6)}
    fig = displacement_history_figure(hist, context=_context(), figsize=(7.0, 3.8))
    assert _overlaps_data(fig) == []
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "alarm −21.1 mm" in labels and "warning −16.8 mm" in labels
    refl = [Reflector("R1", "reference", (0.0, -1.5, 2.0), 0.05), Reflector("M1", "measurement", (8.0, -2.0, 7.0), 0.05)]
    assert _overlaps_data(layout_figure(refl, span_m=40.0)) == []

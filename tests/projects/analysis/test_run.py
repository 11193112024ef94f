"""The analysis document (analysis.json), its figure and its printing: what the numbers mean, with dates."""
from __future__ import annotations

import datetime as dt

import numpy as np

from projects.analysis.models import Event, fit_target
from projects.analysis.run import DAY_NS, _target_json
from projects.store.limits import Limit

ORIGIN = dt.datetime(2026, 1, 5, 9, tzinfo=dt.UTC)


def _doc(rng=None):
    """A target that recovers after its load step, under a kr-rail-like limit (16.842105263157897 mm)."""
    rng = rng or np.random.default_rng(8)
    t = np.arange(0.0, 400.0, 7.0)
    d = (t >= 100) * (-3.0 + 1.5 * (1 - np.exp(-(t - 100) / 40.0))) + rng.normal(0, 0.05, t.size)
    when = (ORIGIN + dt.timedelta(days=100)).date().isoformat()
    fit = fit_target(t, d, np.full(t.size, 0.05), events=[Event(100.0, "slab", "construction", when)])
    origin_ns = int(ORIGIN.timestamp() * 1e9)
    target = _target_json("M3", fit, t, origin_ns, 365.0, Limit(16.842105263157897, 21.05, "kr-rail:0-200"), None)
    doc = {"time_origin": ORIGIN.isoformat(), "baseline": "2026-01-05", "casting_date": None, "warnings": [],
           "temperature_source": None, "targets": [target],
           "events": [{"date": f"{when}T00:00:00+00:00", "label": "slab", "kind": "construction"}]}
    return doc, target, t


def test_the_document_says_what_a_negative_creep_coefficient_means_and_rounds_limits():
    doc, target, t = _doc()
    e = target["events"][0]
    assert e["creep_coefficient"] < 0 and "recovery" in e["note"]
    assert target["measured_mm"] and len(target["measured_mm"]) == len(t)
    curve = target["model_curve"]
    assert len(curve["days"]) == len(curve["mm"]) == len(curve["sigma_mm"]) > 100
    assert min(curve["days"]) >= t[0] and max(curve["days"]) <= t[-1]
    before, after = [v for d, v in zip(curve["days"], curve["mm"], strict=False) if 99.99 <= d <= 100.0]
    assert after - before < -2.5  # the step is kept sharp
    warning = target["projection"]["warning"]
    assert "16.8 mm" in warning and "16.84" not in warning


def test_the_figure_has_dates_the_model_the_data_and_events_and_no_legend_over_them():
    from projects.analysis.figures import target_figure

    doc, target, t = _doc()
    fig = target_figure(doc, target)
    ax = fig.axes[0]
    fig.canvas.draw()
    import matplotlib.dates as mdates

    lo, hi = ax.get_xlim()
    assert ORIGIN - dt.timedelta(days=60) < mdates.num2date(lo) < ORIGIN
    assert ORIGIN + dt.timedelta(days=390) < mdates.num2date(hi) < ORIGIN + dt.timedelta(days=460)
    assert isinstance(ax.xaxis.get_major_formatter(), (mdates.AutoDateFormatter, mdates.ConciseDateFormatter))
    labels = ax.get_legend().get_texts()
    names = " | ".join(x.get_text() for x in labels)
    assert "measured" in names and "fitted model" in names and "1  slab" in names
    legend_box = ax.get_legend().get_window_extent()
    assert legend_box.y1 < ax.get_window_extent().y0  # below the axes, not over the data
    ev = [x for x in ax.texts if x.get_text() == "1"]
    assert ev and ev[0].get_window_extent().y0 >= ax.get_window_extent().y1 - 1  # the event number above the axes


def test_the_command_line_prints_the_notes():
    from app.cli.commands_analysis import print_analysis

    doc, _, _ = _doc()
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        print_analysis(doc)
    out = buf.getvalue()
    assert "event 1 slab" in out and "creep coefficient -" in out
    assert "note: negative creep coefficient: the target moved back after the step (recovery)" in out
    assert "no thermal term" in out and str(DAY_NS) not in out


def test_visits_all_at_the_same_hour_have_no_spread():
    """Found by the years bench: 10 visits at 09:00 round the mean resultant above 1 (a math domain error)."""
    import datetime as dt

    from projects.analysis.run import _aliasing_warnings

    times = [dt.datetime(2026, 1, 5, 9, 0, tzinfo=dt.UTC) + dt.timedelta(weeks=k) for k in range(10)]
    assert not any("times of day" in w for w in _aliasing_warnings(times, None, 0))

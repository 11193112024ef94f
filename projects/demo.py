"""The demo campaign: a year of weekly simulated visits processed like real data."""
from __future__ import annotations

import datetime as dt
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.errors import InputError
from common.files import write_atomic
from common.progress import ProgressCallback, report
from lidar.figures import save_figure
from lidar.layout import layout_from_model
from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
from lidar.simulate.files import simulate_coarse, simulate_fine
from projects.analysis.run import write_analysis
from projects.outputs.exports import export
from projects.outputs.figures import displacement_history_figure
from projects.outputs.report import write_report
from projects.processing.stages import plan_epoch, process
from projects.results.table import displacement_table, to_csv
from projects.series.camera import (
    crossvalidate,
    import_series,
    save_crossval,
    series_records,
    write_crossval_outputs,
)
from projects.series.context import plot_context
from projects.series.environment import add_event, env_records, events, import_env
from projects.series.predictions import import_prediction, predictions
from projects.store.campaign import DB_NAME, Campaign
from projects.store.errors import CampaignError
from projects.store.history import histories
from vision.simulate.series import simulate_series, write_series_csv

#: Visits are on Mondays at this time (UTC); the last one is the latest Monday before the day the demo is built,
#: so a fresh demo never holds a visit, a temperature or a camera reading from the future.
VISIT_TIME = dt.time(9, 0)
CABLE_TIE_WEEK = 20
OCCLUDED_WEEK = 30


def demo_start(weeks: int, *, today: dt.date | None = None) -> dt.datetime:
    """The first visit of a ``weeks``-week demo whose last visit is the latest Monday before ``today``.

    >>> demo_start(52, today=dt.date(2026, 12, 1)).isoformat()  # a Tuesday: the last visit is the day before
    '2025-12-08T09:00:00+00:00'
    >>> demo_start(2, today=dt.date(2026, 11, 30)).isoformat()  # a Monday: the last visit is a week before
    '2026-11-16T09:00:00+00:00'
    """
    today = today or dt.datetime.now(dt.UTC).date()
    last = today - dt.timedelta(days=today.weekday() or 7)
    return dt.datetime.combine(last, VISIT_TIME, tzinfo=dt.UTC) - dt.timedelta(weeks=weeks - 1)


def _start_of(c: Campaign, weeks: int) -> dt.datetime:
    """The demo campaign's first visit: as stored when it was created (a resumed demo keeps its dates)."""
    stored = c.meta("demo_start")
    if stored:
        return dt.datetime.fromisoformat(stored)
    epochs = c.epochs()  # built before the start was stored: its first epoch is week 1
    start = dt.datetime.fromisoformat(epochs[0].datetime) if epochs else demo_start(weeks)
    c.set_meta("demo_start", start.isoformat())
    return start


def _not_after_now(t_ns: int) -> int:
    """``t_ns``, or the current hour when that is earlier (series end at the time the demo is built)."""
    hour = 3600 * 10 ** 9
    now = int(dt.datetime.now(dt.UTC).timestamp()) * 10 ** 9 // hour * hour
    return min(int(t_ns), now)


def midspan_history_m(week: int) -> float:
    """Midspan displacement (positive up): dead-load steps, creep and a seasonal temperature swing.

    Shaped like the dissertation's field test of a railway bridge under construction.
    """
    w = float(week)
    u = 0.0
    if w >= 6:
        u -= 3.0 + 1.5 * (1 - math.exp(-(w - 6) / 15.0))  # superstructure dead load, then creep
    if w >= 18:
        u -= 2.0  # superimposed dead load (track, ballast)
    u += 1.2 * math.sin(2 * math.pi * (w - 16) / 52.0)  # warm summer: the deck rises
    return u / 1000.0


@dataclass
class DemoResult:
    """Where the demo put its campaign and outputs, and what happened in the simulated year."""

    folder: Path
    epochs: int
    csv: Path
    xlsx: Path
    plot: Path
    report: Path
    crossval: Path | None = None
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        lines = [f"demo campaign: {self.folder} ({self.epochs} weekly epochs, processed)",
                 f"  displacements: {self.csv}", f"  all tables:    {self.xlsx}", f"  history plot:  {self.plot}",
                 f"  report:        {self.report}",
                 f"  camera check:  {self.crossval} (dual-camera series against LiDAR)",
                 f"  field files:   {self.folder / 'field'} (ground truth of every week; the last week's scans)"]
        return "\n".join(lines + [f"  {n}" for n in self.notes])


def build_demo(folder: str | os.PathLike, *, weeks: int = 52, seed: int = 2026,
               progress: ProgressCallback | None = None) -> DemoResult:
    """Build (or resume building) the demo campaign in ``folder``."""
    folder = Path(folder)
    if weeks < 2:

        raise InputError("the demo needs at least 2 weeks")
    model = BridgeModel()
    if (folder / DB_NAME).exists():
        c = Campaign.open(folder)
        if c.meta("demo") != "1":
            c.close()
            raise CampaignError(f"{folder}: holds a real campaign, not the demo; choose another folder")
    else:
        layout = layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(seed))
        c = Campaign.create(folder, name="Demo railway bridge (simulated, 40 m span)", layout=layout,
                            span_m=model.span_m)
        c.set_meta("demo", "1")
        c.set_limit("*", "kr-rail:0-200")
    with c:
        start = _start_of(c, weeks)
        add_demo_temperature(c, folder, weeks=weeks, seed=seed, start=start)
        field_dir = folder / "field"
        done = {e.label for e in c.epochs()}
        for w in range(weeks):
            when = start + dt.timedelta(weeks=w)
            label = when.date().isoformat()
            report(progress, w / weeks, f"week {w + 1}/{weeks}")
            res = c.result(label) if label in done else None
            if res is not None and res.stage == "measured":
                continue
            rng = np.random.default_rng(seed * 1000 + w)
            setup = ScannerSetup.random(rng, span_m=model.span_m)
            cond = EpochConditions(midspan_displacement_m=midspan_history_m(w),
                                   cable_ties=("R1",) if w == CABLE_TIE_WEEK else (),
                                   occluded=("M2",) if w == OCCLUDED_WEEK else ())
            visit = field_dir / label
            if label not in done:
                coarse, _ = simulate_coarse(visit, setup=setup, conditions=cond, model=model, seed=seed + w,
                                            coarse_step_deg=0.06)
                c.add_epoch(label, when.isoformat(), coarse, notes=f"scanner at x={setup.position_m[0]:.1f} m, "
                                                                  f"y={setup.position_m[1]:.1f} m (simulated)")
            plan = plan_epoch(c, label)
            fine = visit / "fine.laz"
            if not c.files(label, "fine"):
                fine, _ = simulate_fine(visit, plan.rois, model=model)
                c.import_files(label, [fine], "fine")
            process(c, [label])
            if w < weeks - 1:  # the campaign holds its own copies; keep the last visit's field files as an example
                for p in visit.glob("*.laz"):
                    p.unlink()
        report(progress, 0.97, "exports")
        process(c)
        rows = displacement_table(c)
        csv_path = write_atomic(folder / "displacements.csv", to_csv(rows))
        xlsx = export(c, folder / "campaign.xlsx")
        report(progress, 0.975, "camera series")
        cv_dir = add_demo_camera(c, folder, weeks=weeks, seed=seed, start=start)
        report(progress, 0.978, "temperature, events, design prediction, analysis")
        story = add_demo_story(c, folder, weeks=weeks, seed=seed, start=start)
        report(progress, 0.98, "report")
        rows = displacement_table(c)
        csv_path = write_atomic(folder / "displacements.csv", to_csv(rows))
        plot = save_figure(displacement_history_figure(histories(c), title=c.name, context=plot_context(c)),
                           folder / "displacement_history.png")
        pdf = write_report(c, folder / "report.pdf", author="BridgeSurvey demo")
        day = lambda w: (start + dt.timedelta(weeks=w)).date().isoformat()  # noqa: E731
        notes = [f"week {CABLE_TIE_WEEK + 1} ({day(CABLE_TIE_WEEK)}): a cable tie beside R1; week "
                 f"{OCCLUDED_WEEK + 1} ({day(OCCLUDED_WEEK)}): M2 occluded"] + story
        report(progress, 1.0, "done")
        return DemoResult(folder, len(c.epochs()), csv_path, xlsx, plot, pdf, cv_dir, notes)


THERMAL_MM_PER_DEGC = 1.2 / 10.0  # the history's seasonal 1.2 mm at midspan over a +-10 degC swing
DEAD_LOAD_WEEKS = ((6, "superstructure dead load", 3.0), (18, "track and ballast", 2.0))
DESIGN_OFFSET_MM = 21.59  # the dissertation's alignment of its finite-element curve


def _ns(when: dt.datetime) -> int:
    return int(np.datetime64(when.astimezone(dt.UTC).replace(tzinfo=None), "ns").astype(np.int64))


def demo_temperature(t_ns: np.ndarray, start: dt.datetime) -> np.ndarray:
    """Air temperature of the demo (degC) at ``t_ns`` (UTC ns): the seasonal swing the history follows and a daily one.

    ``start`` is the demo's first visit (:func:`demo_start`).
    """
    t0 = _ns(start)
    w = (t_ns - t0) / (7 * 86400 * 10 ** 9)
    hour = (t_ns / 3.6e12) % 24
    return 12.0 + 10.0 * np.sin(2 * np.pi * (w - 16) / 52.0) + 3.0 * np.sin(2 * np.pi * (hour - 9) / 24.0)


def add_demo_temperature(c: Campaign, folder: Path, *, weeks: int, seed: int, start: dt.datetime) -> None:
    """The air temperature logged on site (hourly), imported before the visits are processed.

    As a surveyor who imports the logger's file with every visit: each visit is processed once with its air
    reading, and the finished demo has nothing stale (imported afterwards, it would make every visit stale).
    """
    if any(r.name == "air-temperature" for r in env_records(c)):
        return
    field = folder / "field"
    field.mkdir(exist_ok=True)
    t0 = _ns(start)
    hour = 3600 * 10 ** 9
    t = np.arange(t0 - 7 * 24 * hour, _not_after_now(t0 + (weeks + 1) * 7 * 24 * hour), hour)
    temp = demo_temperature(t, start) + np.random.default_rng(seed + 11).normal(0, 0.3, t.size)
    lines = ["time,temperature_degC"] + [
        f"{np.datetime_as_string(np.datetime64(int(a), 'ns'), unit='m')}Z,{b:.2f}"
        for a, b in zip(t, temp, strict=False)]
    (field / "temperature.csv").write_text("\n".join(lines) + "\n")
    import_env(c, field / "temperature.csv", kind="temperature", name="air-temperature")


def add_demo_story(c: Campaign, folder: Path, *, weeks: int, seed: int, start: dt.datetime) -> list[str]:
    """The field story told by the demo's imports and analysis.

    The two dead-load events, the design prediction (no temperature,
    offset by 21.59 mm) aligned at week 8, and the analysis in ``analysis/``.
    """
    field = folder / "field"
    field.mkdir(exist_ok=True)
    if not events(c):
        for w, label, _ in DEAD_LOAD_WEEKS:
            if w < weeks - 2:
                add_event(c, date=(start + dt.timedelta(weeks=w - 0.5)).isoformat(), kind="construction", label=label)
    mid = max(2, min(8, weeks - 1))
    if not predictions(c) and weeks > 10:
        rows = ["date,M1,M2,M3,M4,M5"]
        fractions = (0.2, 0.35, 0.5, 0.65, 0.8)
        for day in range(0, weeks * 7 + 30, 7):
            wk = day / 7.0
            u = float(DESIGN_OFFSET_MM)
            if wk >= 6:
                u -= 3.0 + 1.5 * (1 - math.exp(-(wk - 6) / 15.0))
            if wk >= 18:
                u -= 2.0
            when = (start + dt.timedelta(days=day)).date().isoformat()
            rows.append(when + "," + ",".join(f"{u * math.sin(math.pi * f):.3f}" for f in fractions))
        (field / "design-prediction.csv").write_text("\n".join(rows) + "\n")
        import_prediction(c, field / "design-prediction.csv",
                          align_at=(start + dt.timedelta(weeks=mid)).date().isoformat())
    notes = []
    if c.limit_for("M3") is not None and len(c.epochs()) >= 4:
        doc, _ = write_analysis(c, folder / "analysis")
        m3 = next(t for t in doc["targets"] if t["reflector"] == "M3")
        if m3["thermal_mm_per_degC"] is not None:
            notes.append(f"analysis of M3: {m3['thermal_mm_per_degC']:.3f} ± {m3['thermal_sigma']:.3f} mm/°C "
                         f"(simulated {THERMAL_MM_PER_DEGC:.3f}); "
                         + "; ".join(f"{e['label']} {e['step_mm']:+.2f} mm (simulated "
                                     f"{-next(s for _, lab, s in DEAD_LOAD_WEEKS if lab == e['label']):+.2f})"
                                     for e in m3["events"] if e["step_mm"] is not None))
        notes.append(f"analysis: {folder / 'analysis' / 'analysis.json'}")
    return notes


def add_demo_camera(c: Campaign, folder: Path, *, weeks: int, seed: int, start: dt.datetime) -> Path:
    """The dual-camera system's 1-minute series of the midspan target over the campaign.

    Its own zero, 0.2 mm noise, a ten-day outage, a few empty readings), imported and cross-validated.
    """
    t0 = _ns(start)
    week_ns = 7 * 86400 * 10 ** 9

    def truth_mm(t):
        return np.array([midspan_history_m(w) for w in (t - t0) / week_ns]) * 1000.0

    if not any(r.name == "midspan-camera" for r in series_records(c)):
        end = _not_after_now(t0 + (weeks - 1) * week_ns + 86400 * 10 ** 9)
        grid = np.arange(t0 - 86400 * 10 ** 9, end + 1, 3600 * 10 ** 9)
        smooth = truth_mm(grid)  # hourly truth, interpolated to minutes (the history is smooth)
        outage = t0 + 34 * week_ns + 2 * 86400 * 10 ** 9
        t, v = simulate_series(t0 - 86400 * 10 ** 9, end, lambda t: np.interp(t, grid, smooth), noise_mm=0.2,
                               zero_offset_mm=21.6, outages=[(outage, outage + 10 * 86400 * 10 ** 9)],
                               rng=np.random.default_rng(seed + 7))
        path = write_series_csv(folder / "field" / "camera_midspan.csv", t, v, utc_offset_h=9)
        import_series(c, path, name="midspan-camera", reflector="M3")
    cv, cam = crossvalidate(c, series="midspan-camera")
    out = folder / "crossval"
    write_crossval_outputs(cv, cam, out)
    save_crossval(c, cv)
    return out

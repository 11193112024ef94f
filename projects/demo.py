"""The demo campaign: a year of weekly simulated visits processed like real data."""
from __future__ import annotations

import datetime as dt
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from lidar.figures import save_figure
from lidar.layout import layout_from_model
from lidar.progress import ProgressCallback, report
from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
from lidar.simulate.files import simulate_coarse, simulate_fine
from projects.errors import CampaignError
from projects.exports import displacement_table, export, to_csv, write_atomic
from projects.figures import displacement_history_figure
from projects.processing import plan_epoch, process
from projects.store import DB_NAME, Campaign

START = dt.datetime(2026, 1, 5, 9, 0, tzinfo=dt.timezone.utc)
CABLE_TIE_WEEK = 20
OCCLUDED_WEEK = 30


def midspan_history_m(week: int) -> float:
    """Midspan displacement (positive up): dead-load steps, creep and a seasonal temperature swing,
    shaped like the dissertation's field test of a railway bridge under construction."""
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
    folder: Path
    epochs: int
    csv: Path
    xlsx: Path
    plot: Path
    report: Path
    crossval: Optional[Path] = None
    notes: list[str] = field(default_factory=list)

    def summary(self) -> str:
        lines = [f"demo campaign: {self.folder} ({self.epochs} weekly epochs, processed)",
                 f"  displacements: {self.csv}", f"  all tables:    {self.xlsx}", f"  history plot:  {self.plot}",
                 f"  report:        {self.report}",
                 f"  camera check:  {self.crossval} (dual-camera series against LiDAR)",
                 f"  field files:   {self.folder / 'field'} (ground truth of every week; the last week's scans)"]
        return "\n".join(lines + [f"  {n}" for n in self.notes])


def build_demo(folder: str | os.PathLike, *, weeks: int = 52, seed: int = 2026,
               progress: Optional[ProgressCallback] = None) -> DemoResult:
    """Build (or resume building) the demo campaign in ``folder``."""
    folder = Path(folder)
    if weeks < 2:
        from lidar.errors import InputError

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
        with c.transaction() as conn:
            conn.execute("INSERT INTO meta(key, value) VALUES ('demo', '1')")
        c.set_limit("*", "kr-rail:0-200")
    with c:
        field_dir = folder / "field"
        done = {e["label"] for e in c.epochs()}
        for w in range(weeks):
            when = START + dt.timedelta(weeks=w)
            label = when.date().isoformat()
            report(progress, w / weeks, f"week {w + 1}/{weeks}")
            row = c.result_row(label) if label in done else None
            if row is not None and row["stage"] == "measured":
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
        plot = save_figure(displacement_history_figure(rows, title=c.name), folder / "displacement_history.png")
        report(progress, 0.975, "camera series")
        cv_dir = add_demo_camera(c, folder, weeks=weeks, seed=seed)
        report(progress, 0.98, "report")
        from projects.report import write_report

        pdf = write_report(c, folder / "report.pdf", author="BridgeSurvey demo")
        notes = [f"week {CABLE_TIE_WEEK + 1}: a cable tie beside R1; week {OCCLUDED_WEEK + 1}: M2 occluded"]
        report(progress, 1.0, "done")
        return DemoResult(folder, len(c.epochs()), csv_path, xlsx, plot, pdf, cv_dir, notes)


def add_demo_camera(c: Campaign, folder: Path, *, weeks: int, seed: int) -> Path:
    """The dual-camera system's 1-minute series of the midspan target over the campaign (its own zero,
    0.2 mm noise, a ten-day outage, a few empty readings), imported and cross-validated."""
    from projects.camera import crossvalidate, save_crossval, series_rows, write_crossval_outputs
    from projects.camera import import_series
    from vision.simulate.series import simulate_series, write_series_csv

    t0 = np.datetime64(START.replace(tzinfo=None), "ns").astype(np.int64)
    week_ns = 7 * 86400 * 10 ** 9

    def truth_mm(t):
        return np.array([midspan_history_m(w) for w in (t - t0) / week_ns]) * 1000.0

    if not any(r["name"] == "midspan-camera" for r in series_rows(c)):
        end = t0 + (weeks - 1) * week_ns + 86400 * 10 ** 9
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

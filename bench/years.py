"""Years of weekly visits: does a visit cost the same in year ten as in year one? (issue 44)

One bridge, a visit a week with the field physics on (the atmosphere, a range walk with clipped intensities,
the set-up's drift, the deck expanding), each visit added, planned, its fine scans imported and processed as a
surveyor would (``add-epoch``, ``plan``, ``add-fine``, ``process`` through the package's functions, nothing
cached between visits but what the campaign stores). At each checkpoint it prints the newest visit's time
and peak memory for add-epoch + plan + fine import, for process, how many earlier visits that processing
computed again, and the time of ``status``, ``displacements``, the last year's ``report`` and ``export``, and
the campaign folder's size.

The field model is fitted over the baseline and the newest ``field_window`` visits (the campaign's setting,
default 52): a visit older than that keeps the values computed while it was among them, so the weekly work
is bounded. The scenes are simulated afresh every week (coarse scans at 0.06 degrees, as the demo's). A visit
planning refuses (too little of a symmetric bridge seen) is counted and left imported, as a surveyor would
scan again.

Usage: ``./run bench years [--visits N] [--checkpoints 52,156,520] [--window W] [--small]`` (``--small``:
8 visits, window 3, checkpoints 4 and 8).
"""
from __future__ import annotations

import argparse
import datetime as dt
import resource
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _harness import figures, small_mode, write_figure  # noqa: E402

from common.errors import SurveyError  # noqa: E402
from lidar.layout import layout_from_model  # noqa: E402
from lidar.simulate.bridge import BridgeModel  # noqa: E402
from lidar.simulate.campaign import random_conditions  # noqa: E402
from lidar.simulate.effects import InverseSquareWalk, VisitTiming  # noqa: E402
from lidar.simulate.files import simulate_coarse, simulate_fine  # noqa: E402
from lidar.simulate.setup import ScannerSetup  # noqa: E402
from projects.outputs.exports import export  # noqa: E402
from projects.outputs.report import ReportScope, write_report  # noqa: E402
from projects.processing.stages import plan_epoch, process, set_parameter  # noqa: E402
from projects.results.status import campaign_status  # noqa: E402
from projects.results.table import displacement_table  # noqa: E402
from projects.store.campaign import Campaign  # noqa: E402

START = dt.datetime(2026, 1, 5, 9, 0, tzinfo=dt.UTC)


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _size_mb(folder: Path) -> float:
    """The folder's size on disk: its files, links not followed (a scan's link under scans/by-visit/ costs nothing)."""
    return sum(p.lstat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6


def run(root: Path, visits: int, checkpoints: list[int], window: int, seed: int = 44) -> list[dict]:
    model = BridgeModel()
    rng = np.random.default_rng(seed)
    field_dir, camp = root / "field", root / "campaign"
    field_dir.mkdir(parents=True)
    layout = layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(seed + 1))
    rows = []
    refused: list[str] = []
    with Campaign.create(camp, name="ten years", layout=layout, span_m=model.span_m) as c:
        set_parameter(c, "field_window", str(window))
        for k in range(visits):
            label = f"w{k + 1:04d}"
            cond = random_conditions(model, rng, ppm=(-30, 30), max_walk_m=None, clipped_fraction=(0.1, 0.3),
                                     temperature_c=(-15, 15), drift_arcsec_per_h=20.0)
            cond = replace(cond, range_walk=InverseSquareWalk(0.003, 15.0),
                           timing=VisitTiming(start_s=0.0, gap_s=30.0, duration="lines"))
            setup = ScannerSetup.random(rng, span_m=model.span_m)
            visit = field_dir / label
            coarse, _ = simulate_coarse(visit, setup=setup, conditions=cond, model=model, seed=seed + k,
                                        coarse_step_deg=0.06)
            before = _peak_mb()

            def add_and_plan(label=label, k=k, coarse=coarse):
                c.add_epoch(label, (START + dt.timedelta(weeks=k)).isoformat(), coarse)
                return plan_epoch(c, label)

            try:
                plan, t_add = _timed(add_and_plan)
            except SurveyError as exc:  # refused at planning, in one line (a surveyor would scan again)
                refused.append(f"{label}: {str(exc).splitlines()[0][:100]}")
                continue
            fine, _ = simulate_fine(visit, plan.rois, model=model)
            _, t_fine = _timed(lambda: c.import_files(label, [fine], "fine"))  # noqa: B023
            summary, t_proc = _timed(lambda: process(c, [label]))  # noqa: B023
            for p in visit.glob("*.laz"):  # the campaign keeps its own copies
                p.unlink()
            if k + 1 not in checkpoints:
                continue
            recomputed = [e for e in summary.displacement_epochs if e != label]
            _, t_status = _timed(lambda: campaign_status(c))
            _, t_table = _timed(lambda: displacement_table(c))
            last_year = c.epochs()[max(0, k - 51)].label
            scope = ReportScope(start=last_year, end=label)
            _, t_report = _timed(lambda scope=scope: write_report(c, root / "report.pdf", scope))
            _, t_export = _timed(lambda: export(c, root / "campaign.xlsx"))
            rows.append({"visits": k + 1, "add_plan_fine_s": t_add + t_fine, "process_s": t_proc,
                         "recomputed": len(recomputed), "status_s": t_status, "displacements_s": t_table,
                         "report_last_year_s": t_report, "export_s": t_export, "peak_mb": max(before, _peak_mb()),  # the process's so far
                         "folder_mb": _size_mb(camp), "refused": len(refused)})
            r = rows[-1]
            print(f"  {r['visits']:4d} visits: add+plan+fine {r['add_plan_fine_s']:.1f} s, process {r['process_s']:.1f} s "
                  f"({r['recomputed']} earlier visits recomputed), status {r['status_s']:.2f} s, displacements "
                  f"{r['displacements_s']:.2f} s, report {r['report_last_year_s']:.1f} s, export {r['export_s']:.1f} s, "
                  f"folder {r['folder_mb']:.0f} MB, {r['refused']} visits refused at planning so far", flush=True)
    return rows


def table(rows: list[dict], window: int) -> str:
    lines = [f"| visits | add-epoch + plan + fine import s | process s | earlier visits recomputed (window {window}) "
             "| status s | displacements s | report of the last year s | export s | peak memory so far MB | folder MB | "
             "visits refused at planning |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['visits']} | {r['add_plan_fine_s']:.1f} | {r['process_s']:.1f} | {r['recomputed']} | "
                     f"{r['status_s']:.2f} | {r['displacements_s']:.2f} | {r['report_last_year_s']:.1f} | "
                     f"{r['export_s']:.1f} | {r['peak_mb']:.0f} | {r['folder_mb']:.0f} | {r['refused']} |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    small, argv = small_mode(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--visits", type=int, default=8 if small else 520)
    ap.add_argument("--checkpoints", default="4,8" if small else "52,156,520")
    ap.add_argument("--window", type=int, default=3 if small else 52)
    args = ap.parse_args(argv)
    checkpoints = [int(x) for x in args.checkpoints.split(",") if int(x) <= args.visits]
    with tempfile.TemporaryDirectory() as tmp:
        rows = run(Path(tmp), args.visits, checkpoints, args.window)
    print(table(rows, args.window))
    first, last = rows[0], rows[-1]
    figures(visits=last["visits"], window=args.window, recomputed_last=last["recomputed"],
            process_ratio_last_to_first=last["process_s"] / max(first["process_s"], 1e-9),
            status_s_last=last["status_s"], folder_mb_last=last["folder_mb"])
    if not small:
        write_figure("years", table(rows, args.window), argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

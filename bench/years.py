"""Years of weekly visits: does a visit cost the same in year ten as in year one? (issue 44)

One bridge, a visit a week with the field physics on (the atmosphere, a range walk with clipped intensities,
the set-up's drift, the deck expanding). Every visit is added, planned, its fine scans imported and processed by
the product (``add-epoch``, ``plan``, ``add-fine``, ``process`` through the package's functions, nothing cached
between visits but what the campaign stores). At each checkpoint the newest visit goes through the weekly cycle
alone and is timed: its add-epoch + plan + fine import and its processing, with peak memory and how many earlier
visits that processing computed again; then ``status``, ``displacements``, ``analyse``, the last year's ``report``
and ``export``, the application opening the campaign (the main window, offscreen, in a process of its own) and
drawing one target's history, the campaign folder's size and the machine's load (it is shared).

Saving time (the product's work is all done, the simulator's is not repeated):

- **Scenes reused.** ``--distinct`` visits (default 52: a year of weather, set-ups and deck states) are simulated
  once; visit k takes scene k mod 52 with its own date. A reused scan gets its own bytes (its LAS header's
  project GUID carries the visit's number, the points are the same), so the campaign's import refuses nothing and
  stores every visit's copy as a surveyor's would. With the default checkpoints every checkpoint visit (52, 156,
  520) is the same scene: the times at the checkpoints differ only by the campaign's length.
- **Visits between checkpoints processed in batches** of ``--batch`` visits (default 26, at most the field window,
  so every visit is fitted while it is among the window's newest): each visit is added, planned and its fine scans
  imported one by one, then ``process`` runs over the batch. Before a checkpoint the batch in hand is processed,
  so the checkpoint visit's processing is the weekly one: one new visit, the window re-fitted.

The field model is fitted over the baseline and the newest ``field_window`` visits (the campaign's setting,
default 52): a visit older than that keeps the values computed while it was among them, so the weekly work is
bounded. Whether that holds without cost to the values is checked: every visit's displacements are kept as first
processed and just after it left the window, and compared at the end with their σ at that time ("beyond σ"
counts the target values that moved more than one σ). A visit planning refuses (too little of a symmetric bridge
seen) is counted and left imported, as a surveyor would scan again.

Usage: ``./run bench years [--visits N] [--checkpoints 52,156,520] [--window W] [--distinct D] [--batch B]
[--no-app] [--keep DIR] [--status-of CAMPAIGN] [--small]`` (``--small``: 8 visits, window 3, 4 distinct scenes, batches of 2, checkpoints 4 and 8).
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _harness import ROOT, figures, small_mode, write_figure  # noqa: E402
from bench_campaign import variant  # noqa: E402

from common.errors import SurveyError  # noqa: E402
from lidar.layout import layout_from_model  # noqa: E402
from lidar.simulate.bridge import BridgeModel  # noqa: E402
from lidar.simulate.campaign import random_conditions  # noqa: E402
from lidar.simulate.effects import InverseSquareWalk, VisitTiming  # noqa: E402
from lidar.simulate.files import simulate_coarse, simulate_fine  # noqa: E402
from lidar.simulate.setup import ScannerSetup  # noqa: E402
from projects.analysis.run import write_analysis  # noqa: E402
from projects.outputs.exports import export  # noqa: E402
from projects.outputs.report import ReportScope, write_report  # noqa: E402
from projects.processing.stages import plan_epoch, process, set_parameter  # noqa: E402
from projects.results.status import campaign_status  # noqa: E402
from projects.results.table import displacement_table  # noqa: E402
from projects.store.campaign import Campaign  # noqa: E402

START = dt.datetime(2026, 1, 5, 9, 0, tzinfo=dt.UTC)


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _timed(fn, *args):
    t0 = time.perf_counter()
    out = fn(*args)
    return out, time.perf_counter() - t0


def _size_mb(folder: Path) -> float:
    """The folder's size on disk: its files, links not followed (a scan's link under scans/by-visit/ costs nothing)."""
    return sum(p.lstat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()) / 1e6


@dataclass
class Scene:
    """One simulated visit, reused every ``distinct`` weeks: its folder (coarse scan and scene spec) and, once
    planned, its fine scan."""
    folder: Path
    coarse: Path
    fine: Path | None = None


class Scenes:
    """The simulator's visits, each simulated on its first use."""

    def __init__(self, root: Path, model: BridgeModel, distinct: int, seed: int):
        self.root, self.model, self.distinct, self.seed = root, model, distinct, seed
        self.rng = np.random.default_rng(seed)
        self.scenes: list[Scene] = []

    def get(self, k: int) -> Scene:
        j = k % self.distinct
        while len(self.scenes) <= j:  # in order: the random draws as the bench always made them
            n = len(self.scenes)
            cond = random_conditions(self.model, self.rng, ppm=(-30, 30), max_walk_m=None,
                                     clipped_fraction=(0.1, 0.3), temperature_c=(-15, 15), drift_arcsec_per_h=20.0)
            cond = replace(cond, range_walk=InverseSquareWalk(0.003, 15.0),
                           timing=VisitTiming(start_s=0.0, gap_s=30.0, duration="lines"))
            setup = ScannerSetup.random(self.rng, span_m=self.model.span_m)
            folder = self.root / f"scene{n:03d}"
            coarse, _ = simulate_coarse(folder, setup=setup, conditions=cond, model=self.model, seed=self.seed + n,
                                        coarse_step_deg=0.06)
            self.scenes.append(Scene(folder, coarse))
        return self.scenes[j]

    def fine(self, k: int, plan) -> Path:
        """The scene's fine scan of ``plan``'s windows (simulated at the scene's first plan; the same coarse scan
        plans the same windows)."""
        s = self.get(k)
        if s.fine is None:
            s.fine, _ = simulate_fine(s.folder, plan.rois, model=self.model)
        return s.fine


def _values(c: Campaign) -> dict[tuple[str, str], tuple[float, float]]:
    return {(r["epoch"], r["reflector"]): (r["displacement_mm"], r["sigma_mm"]) for r in displacement_table(c)
            if r["displacement_mm"] is not None and r["sigma_mm"] is not None and r["epoch"] != r["baseline"]}


class Drift:
    """Every visit's values as first processed and just after it left the field window, against the end."""

    def __init__(self, window: int):
        self.window = window
        self.first: dict = {}
        self.left: dict = {}

    def seen(self, c: Campaign, measured: list[str]) -> None:
        vals = _values(c)
        for key, v in vals.items():
            self.first.setdefault(key, v)
        out = set(measured[1:max(1, len(measured) - self.window)]) if self.window else set()
        for key, v in vals.items():
            if key[0] in out:
                self.left.setdefault(key, v)

    def beyond(self, c: Campaign) -> dict:
        end = _values(c)

        def count(kept: dict) -> tuple[int, int, float]:
            pairs = [(end[k], v) for k, v in kept.items() if k in end]
            over = sum(abs(e[0] - v[0]) > v[1] for e, v in pairs)
            worst = max((abs(e[0] - v[0]) / v[1] for e, v in pairs if v[1] > 0), default=0.0)
            return len(pairs), over, worst

        n_first, over_first, worst_first = count(self.first)
        n_left, over_left, worst_left = count(self.left)
        return {"values": n_first, "beyond_sigma_since_first": over_first, "worst_sigmas_since_first": worst_first,
                "left_window": n_left, "beyond_sigma_since_left": over_left, "worst_sigmas_since_left": worst_left}


def status_command_s(folder: Path, timeout_s: float = 300.0, *, repeat: int = 3) -> tuple[float, float]:
    """``bridgesurvey status`` on ``folder`` as a surveyor runs it: a process of its own, start-up included.

    The fastest of ``repeat`` runs: (wall s, CPU s of that run, user + system). On a machine shared with other
    work the wall time stretches by the load (two cores at a load of 5: about twice); the CPU time does not.
    """
    best = (float("inf"), float("nan"))
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        res = subprocess.run([sys.executable, "-m", "app.cli.main", "status", str(folder)], cwd=ROOT,
                             capture_output=True, text=True, timeout=timeout_s)
        took = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if res.returncode != 0:
            raise RuntimeError(f"status failed on the campaign: {res.stderr[-1500:]}")
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        best = min(best, (took, cpu))
    return best


def app_times(folder: Path, timeout_s: float = 300.0) -> dict:
    """The application opening ``folder`` in a process of its own (offscreen): start, open, one target's history."""
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--app-child", str(folder)], cwd=ROOT,
                         env=env, capture_output=True, text=True, timeout=timeout_s)
    line = next((ln for ln in res.stdout.splitlines() if ln.startswith("@@")), None)
    if res.returncode != 0 or line is None:
        raise RuntimeError(f"the application did not open the campaign: {res.stderr[-1500:]}")
    return json.loads(line[2:])


def _drawn(app, canvas) -> None:
    """Let the event loop run until the canvas has drawn what its view asked (its idle draw, once)."""
    app.processEvents()
    while getattr(canvas, "_draw_pending", False):
        app.processEvents()


def _app_child(folder: str) -> int:
    t0 = time.perf_counter()
    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication

    from app.gui.main_window import SMALL_SCREEN, MainWindow

    app = QApplication.instance() or QApplication([])
    with tempfile.TemporaryDirectory() as tmp:
        QSettings.setPath(QSettings.IniFormat, QSettings.UserScope, tmp)  # a fresh user: the displacements tab first
        win = MainWindow(demo_dir=str(Path(tmp) / "no-demo"))
        win.resize(*SMALL_SCREEN)
        win.show()
        app.processEvents()
        t_start = time.perf_counter() - t0
        t1 = time.perf_counter()
        if not win.open_campaign(folder):
            print("the window refused the campaign", file=sys.stderr)
            return 1
        _drawn(app, win.displacements.canvas)  # every target's history drawn, as the window shows it
        t_open = time.perf_counter() - t1
        targets = sorted(win.displacements.histories)
        rid = targets[len(targets) // 2]
        t2 = time.perf_counter()
        win.state.select(reflector=rid)
        win.displacements.show_target(rid)
        _drawn(app, win.displacements.canvas)
        t_history = time.perf_counter() - t2
        epochs = len(win.state.snapshot.epochs)
        win.close()
    print("@@" + json.dumps({"start_s": t_start, "open_s": t_open, "history_s": t_history, "target": rid,
                             "epochs": epochs}))
    return 0


def run(root: Path, visits: int, checkpoints: list[int], window: int, *, distinct: int, batch: int,
        app: bool = True, seed: int = 44) -> tuple[list[dict], dict]:
    model = BridgeModel()
    field_dir, camp = root / "field", root / "campaign"
    field_dir.mkdir(parents=True)
    scenes = Scenes(root / "scenes", model, distinct, seed)
    layout = layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(seed + 1))
    rows: list[dict] = []
    refused: list[str] = []
    measured: list[str] = []
    pending: list[str] = []
    drift = Drift(window)
    t_run = time.perf_counter()

    def process_batch(c: Campaign) -> None:
        if pending:
            process(c, list(pending))
            measured.extend(pending)
            pending.clear()
            drift.seen(c, measured)

    c = Campaign.create(camp, name="ten years", layout=layout, span_m=model.span_m)
    try:
        set_parameter(c, "field_window", str(window))
        due = sorted(checkpoints)
        for k in range(visits):
            label = f"w{k + 1:04d}"
            check = bool(due) and k + 1 >= due[0]  # a refused checkpoint visit: the next one is timed instead
            if check or len(pending) >= batch:
                process_batch(c)
            visit = field_dir / label
            visit.mkdir(parents=True)
            coarse = variant(scenes.get(k).coarse, visit / "coarse.laz", k + 1)
            before = _peak_mb()

            def add_and_plan(c=c, label=label, k=k, coarse=coarse):
                c.add_epoch(label, (START + dt.timedelta(weeks=k)).isoformat(), coarse)
                return plan_epoch(c, label)

            try:
                plan, t_add = _timed(add_and_plan)
            except SurveyError as exc:  # refused at planning, in one line (a surveyor would scan again)
                refused.append(f"{label}: {str(exc).splitlines()[0][:100]}")
                shutil.rmtree(visit)
                continue
            fine = variant(scenes.fine(k, plan), visit / "fine.laz", k + 1)
            _, t_fine = _timed(c.import_files, label, [fine], "fine")
            shutil.rmtree(visit)  # the campaign keeps its own copies
            if not check:
                pending.append(label)
                continue
            due.pop(0)
            summary, t_proc = _timed(process, c, [label])
            measured.append(label)
            peak = max(before, _peak_mb())  # the process's so far
            drift.seen(c, measured)
            recomputed = [e for e in summary.displacement_epochs if e != label]
            _, t_status = _timed(campaign_status, c)
            _, t_table = _timed(displacement_table, c)
            _, t_analyse = _timed(write_analysis, c, root / "analysis")
            last_year = c.epochs()[max(0, k - 51)].label
            scope = ReportScope(start=last_year, end=label)
            _, t_report = _timed(write_report, c, root / "report.pdf", scope)
            _, t_export = _timed(export, c, root / "campaign.xlsx")
            gui = {"open_s": None, "history_s": None, "start_s": None}
            c.close()  # the writer's lock let go while the command and the application read, as a surveyor's would
            t_status_cmd, cpu_status_cmd = status_command_s(camp)
            if app:
                gui = app_times(camp)
            c = Campaign.open(camp)
            rows.append({"visits": k + 1, "add_plan_fine_s": t_add + t_fine, "process_s": t_proc,
                         "recomputed": len(recomputed), "status_s": t_status, "status_cmd_s": t_status_cmd,
                         "status_cmd_cpu_s": cpu_status_cmd,
                         "displacements_s": t_table,
                         "analyse_s": t_analyse, "report_last_year_s": t_report, "export_s": t_export,
                         "app_open_s": gui["open_s"], "app_history_s": gui["history_s"],
                         "app_start_s": gui["start_s"], "peak_mb": peak, "folder_mb": _size_mb(camp),
                         "refused": len(refused), "load": os.getloadavg(), "elapsed_min": (time.perf_counter()
                                                                                        - t_run) / 60})
            r = rows[-1]
            app_text = "" if r["app_open_s"] is None else \
                f", app opens {r['app_open_s']:.2f} s, history {r['app_history_s']:.2f} s"
            print(f"  {r['visits']:4d} visits: add+plan+fine {r['add_plan_fine_s']:.1f} s, process {r['process_s']:.1f} s "
                  f"({r['recomputed']} earlier visits recomputed), status {r['status_s']:.2f} s (the command "
                  f"{r['status_cmd_s']:.2f} s, {r['status_cmd_cpu_s']:.2f} s of CPU), displacements "
                  f"{r['displacements_s']:.2f} s, analyse {r['analyse_s']:.1f} s, report {r['report_last_year_s']:.1f} s, "
                  f"export {r['export_s']:.1f} s{app_text}, folder {r['folder_mb']:.0f} MB, "
                  f"{r['refused']} visits refused at planning so far, load {r['load'][0]:.1f}/{r['load'][1]:.1f}, "
                  f"{r['elapsed_min']:.0f} min in", flush=True)
        process_batch(c)
        kept = drift.beyond(c)
    finally:
        c.close()
    for line in refused:
        print(f"  refused: {line}")
    return rows, kept


def _opt(v, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def table(rows: list[dict], window: int) -> str:
    lines = [f"| visits | add-epoch + plan + fine import s | process s | earlier visits recomputed (window {window}) "
             "| status s (in this process) | `bridgesurvey status` s (the command: wall / CPU) | displacements s | analyse s | report of the last year s | export s | application opens s "
             "| history plot s | peak memory so far MB | folder MB | visits refused at planning | load (1 min / 5 min) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['visits']} | {r['add_plan_fine_s']:.1f} | {r['process_s']:.1f} | {r['recomputed']} | "
                     f"{r['status_s']:.2f} | {r['status_cmd_s']:.2f} / {r['status_cmd_cpu_s']:.2f} | {r['displacements_s']:.2f} | {r['analyse_s']:.1f} | "
                     f"{r['report_last_year_s']:.1f} | {r['export_s']:.1f} | {_opt(r['app_open_s'], '.2f')} | "
                     f"{_opt(r['app_history_s'], '.2f')} | {r['peak_mb']:.0f} | {r['folder_mb']:.0f} | "
                     f"{r['refused']} | {r['load'][0]:.1f} / {r['load'][1]:.1f} |")
    return "\n".join(lines)


def kept_text(kept: dict, window: int) -> str:
    return (f"Earlier visits' values against their σ at the end (window {window}): of {kept['values']} target values, "
            f"{kept['beyond_sigma_since_first']} moved more than their σ since first processed (worst "
            f"{kept['worst_sigmas_since_first']:.2f} σ); of {kept['left_window']} that left the window, "
            f"{kept['beyond_sigma_since_left']} moved more than their σ since (worst "
            f"{kept['worst_sigmas_since_left']:.2f} σ).")


def main(argv: list[str]) -> int:
    if argv[:1] == ["--app-child"]:
        return _app_child(argv[1])
    small, argv = small_mode(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--visits", type=int, default=8 if small else 520)
    ap.add_argument("--checkpoints", default="4,8" if small else "52,156,520")
    ap.add_argument("--window", type=int, default=3 if small else 52)
    ap.add_argument("--distinct", type=int, default=4 if small else 52)
    ap.add_argument("--batch", type=int, default=2 if small else 26)
    ap.add_argument("--no-app", action="store_true", help="leave out the application's open and history plot")
    ap.add_argument("--status-of", metavar="CAMPAIGN", help="only time `bridgesurvey status` on an existing campaign "
                    "(one --keep left, say) and print the load: the command re-measured after a change without "
                    "building ten years again")
    ap.add_argument("--keep", metavar="DIR", help="keep the campaign in DIR (an empty or new folder) to look at it "
                    "afterwards, e.g. to profile a command on a long campaign")
    args = ap.parse_args(argv)
    if args.status_of:
        try:
            with Campaign.open(args.status_of, writable=False) as c:
                n = len(c.epochs())
        except SurveyError as exc:
            ap.error(f"--status-of: {exc}")
        wall, cpu = status_command_s(Path(args.status_of))
        load = os.getloadavg()
        print(f"status of {args.status_of} ({n} visits): {wall:.2f} s ({cpu:.2f} s of CPU), the fastest of 3; "
              f"load {load[0]:.1f}/{load[1]:.1f}")
        return 0
    if args.window and args.batch > args.window:
        ap.error(f"--batch {args.batch} is larger than --window {args.window}: a batch's first visits would never "
                 "be fitted among the window's newest")
    checkpoints = [int(x) for x in args.checkpoints.split(",") if int(x) <= args.visits]
    if args.keep and Path(args.keep).exists() and any(Path(args.keep).iterdir()):
        ap.error(f"--keep {args.keep}: the folder is not empty")
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        rows, kept = run(root, args.visits, checkpoints, args.window, distinct=args.distinct,
                         batch=max(1, args.batch), app=not args.no_app)
    text = table(rows, args.window) + "\n\n" + kept_text(kept, args.window)
    print(text)
    first, last = rows[0], rows[-1]
    figures(visits=last["visits"], window=args.window, recomputed_last=last["recomputed"],
            process_ratio_last_to_first=last["process_s"] / max(first["process_s"], 1e-9),
            status_s_last=last["status_s"], status_cmd_s_last=last["status_cmd_s"],
            status_cmd_cpu_s_last=last["status_cmd_cpu_s"], folder_mb_last=last["folder_mb"],
            app_open_s_last=last["app_open_s"],
            history_s_last=last["app_history_s"], values_kept=kept["values"],
            beyond_sigma_since_left=kept["beyond_sigma_since_left"],
            beyond_sigma_since_first=kept["beyond_sigma_since_first"])
    if not small:
        write_figure("years", text, argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

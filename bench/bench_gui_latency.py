"""The application's responsiveness through a weekly visit: the longest the interface thread stays blocked per action.

A ``QTimer`` ticks every 50 ms on the main (interface) thread while the bench drives the real main window at
1366×768 as a surveyor would: a new campaign, a visit added, planned, one of its windows dragged and the edited plan
saved, the fine scans added, a check that asks for a re-scan, processing anyway, a second visit, the target's fine
scan inspected, the 3-D view (the scan, then its change), the report, and tab changes. For every action the bench
reports the longest gap between two ticks from the moment the action starts until its job has ended and its result
is drawn; the issue's target is no gap above 0.5 s over the whole visit (41: "the window answers within 0.2 s",
"never blocks the interface for more than 0.5 s").

Needs an X display with OpenGL for the 3-D view; without one it re-runs itself under Xvfb (software OpenGL, so the
3-D hand-over is slower than on a real graphics card). Usage: ``./run bench bench_gui_latency`` (coarse scans at
0.06°, about 1.2 M points each) or ``--small`` (0.12°, about 0.3 M points). ``BENCH_SHOTS=DIR`` saves a picture
of the window after each action; ``BENCH_STALLS=1`` prints where the interface thread (and the worker) was during
each pause.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from _harness import ROOT, figures, small_mode, write_figure

#: The interface must answer within this many seconds during every action (issue 41's target).
TARGET_S = 0.5
#: The timer's interval (ms).
TICK_MS = 50


class Ticks:
    """Times of a 50 ms timer on the interface thread; the longest gap over a span of time."""

    def __init__(self):
        from PySide6.QtCore import Qt, QTimer

        self.times = [time.perf_counter()]
        self.timer = QTimer()
        self.timer.setTimerType(Qt.PreciseTimer)
        self.timer.setInterval(TICK_MS)
        self.timer.timeout.connect(lambda: self.times.append(time.perf_counter()))
        self.timer.start()
        if os.environ.get("BENCH_STALLS"):  # a diagnosis: where the interface thread was while it did not tick
            import threading
            import traceback

            main = threading.main_thread().ident

            def watch():
                while self.timer.isActive():
                    time.sleep(0.1)
                    stalled = time.perf_counter() - self.times[-1]
                    if stalled > 0.2:
                        frames = traceback.extract_stack(sys._current_frames().get(main))
                        ours = [f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in frames
                                if "site-packages" not in f.filename and "<frozen" not in f.filename][-6:]
                        last = frames[-1]
                        print(f"STALL {stalled:.1f} s: {' > '.join(ours)} | {Path(last.filename).name}:{last.name}",
                              flush=True)
                        for ident, fr in sys._current_frames().items():  # the worker, when it held the lock
                            if ident not in (main, threading.get_ident()):
                                st = traceback.extract_stack(fr)
                                ours = [f"{Path(f.filename).name}:{f.lineno} {f.name}" for f in st
                                        if "site-packages" not in f.filename and "threading" not in f.filename][-4:]
                                print(f"    worker: {' > '.join(ours)} | {Path(st[-1].filename).name}:{st[-1].name}"
                                      f":{st[-1].lineno}", flush=True)
            threading.Thread(target=watch, daemon=True).start()

    def longest_gap(self, t0: float, t1: float) -> float:
        t = np.asarray(self.times + [time.perf_counter()])
        gaps = np.diff(t)
        # every gap that overlaps [t0, t1]: the one the action started in, through the one it ended in
        on = (t[1:] >= t0) & (t[:-1] <= t1)
        return float(gaps[on].max()) if on.any() else 0.0


def _field(folder: Path, step_deg: float) -> Path:
    from lidar.layout import layout_from_model, write_layout_csv
    from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
    from lidar.simulate.files import simulate_coarse

    model = BridgeModel()
    folder.mkdir(parents=True, exist_ok=True)
    write_layout_csv(layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(1)), folder / "layout.csv")
    visits = ((ScannerSetup((14.0, -12.0, 1.5), heading_deg=40.0), EpochConditions()),
              (ScannerSetup((24.0, -15.0, 1.4), heading_deg=200.0), EpochConditions(midspan_displacement_m=-0.004)))
    for k, (setup, cond) in enumerate(visits):
        simulate_coarse(folder / f"v{k}", setup=setup, conditions=cond, model=model, seed=10 + k,
                        coarse_step_deg=step_deg)
    return folder


def run(step_deg: float, small: bool) -> None:
    from PySide6.QtCore import QDate, QDateTime, QPointF, QSettings, QTime, QTimeZone
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication, QFileDialog, QMessageBox

    sys.path.insert(0, str(ROOT))
    from app.gui.dialogs import AddEpochDialog, NewCampaignDialog
    from app.gui.main_window import SMALL_SCREEN, MainWindow
    from app.gui.worker import preload_native_modules
    from lidar.simulate.files import simulate_fine
    from projects.store.campaign import Campaign
    from tests.app.gui.helpers import answer, drag, menu_action

    tmp = Path(tempfile.mkdtemp(prefix="bench-gui-latency-"))
    try:
        t = time.perf_counter()
        field = _field(tmp / "field", step_deg)
        print(f"field simulated in {time.perf_counter() - t:.0f} s (coarse step {step_deg}°)")
        _app = QApplication.instance() or QApplication([])  # kept alive for the run
        QSettings.setPath(QSettings.IniFormat, QSettings.UserScope, str(tmp / "settings"))
        chosen: list = []
        QFileDialog.getOpenFileNames = staticmethod(lambda *a, **k: (chosen.pop(0), ""))
        QFileDialog.getSaveFileName = staticmethod(lambda *a, **k: (str(chosen.pop(0)), ""))
        QMessageBox.question = staticmethod(lambda *a, **k: QMessageBox.Yes)  # "process anyway", "save anyway"
        errors: list = []
        QMessageBox.critical = staticmethod(lambda parent, title, text, *a, **k: errors.append((title, text)))
        preload_native_modules()  # as the application's start does, before its window shows (app/gui/main.py)
        win = MainWindow(demo_dir=str(tmp / "no-demo"))
        win.resize(*SMALL_SCREEN)
        win.show()
        QTest.qWaitForWindowExposed(win)
        ticks = Ticks()
        rows: list[tuple[str, float, float]] = []
        camp = tmp / "bridge"
        shots = Path(os.environ["BENCH_SHOTS"]) if os.environ.get("BENCH_SHOTS") else None
        if shots is not None:
            shots.mkdir(parents=True, exist_ok=True)
        rescans = 0

        def wait(ms: int) -> None:
            end = time.perf_counter() + ms / 1000
            while time.perf_counter() < end:
                QTest.qWait(10)

        def action(name: str, fn) -> None:
            wait(150)  # ticks again after the bench's own work (simulating the fine scans) before the action
            t0 = time.perf_counter()
            fn()
            while win.jobs.busy:
                QTest.qWait(10)
            wait(300)  # the job's result handed to the views, and what they do with it
            t1 = time.perf_counter()
            gap = ticks.longest_gap(t0, t1)
            rows.append((name, gap, t1 - t0))
            if shots is not None:  # what the window showed at the end of the action, to look at
                win.grab().save(str(shots / f"{len(rows):02d}-{name.replace(':', '').replace(' ', '-')}.png"))
            print(f"{name:<48s} longest gap {gap * 1000:7.0f} ms   ({t1 - t0:6.1f} s)", flush=True)

        def do(menu: str, entry: str):
            return lambda: menu_action(win, menu, entry).trigger()

        answer(NewCampaignDialog, lambda d: (d.folder.edit.setText(str(camp)), d.name.setText("Latency bridge"),
                                             d.layout_csv.edit.setText(str(field / "layout.csv")),
                                             d.span.setValue(40.0)))
        action("new campaign", do("File", "New campaign…"))
        for k, label in enumerate(("v0", "v1")):
            def fill(d, k=k, label=label):
                d.coarse.edit.setText(str(field / f"v{k}" / "coarse.laz"))
                d.when.setDateTime(QDateTime(QDate(2026, 3, 2 + 7 * k), QTime(9, 0), QTimeZone.utc()))
                d.label.setText(label)
            answer(AddEpochDialog, fill)
            action(f"{label}: add epoch (import the coarse scan)", do("Epoch", "Add epoch…"))
            action(f"{label}: plan", do("Epoch", "Plan the selected epoch"))
            if k == 0:
                win.state.request_view("map")
                wait(200)
                mv = win.map_view
                item = next(it for it in mv.items if it.roi.reflector == "M3")

                def edit(item=item, mv=mv):
                    win.state.select(reflector="M3")
                    r = item.scene_rect()
                    drag(mv.view, r.center(), r.center() + QPointF(r.width() * 0.45, r.height() * 0.3))
                action(f"{label}: select M3 and drag its window", edit)
                action(f"{label}: save the edited plan", mv.save_btn.click)
            with Campaign.open(camp, writable=False) as c:
                plan = c.plan(label)
            rois = plan.rois
            if k == 0:  # the scanner ran M2's window at twice the planned steps: a quarter of its points
                rois = [r if r.reflector != "M2" else replace(r, window=replace(
                    r.window, phi_step_deg=2 * r.window.phi_step_deg, theta_step_deg=2 * r.window.theta_step_deg))
                    for r in rois]
            fine, _ = simulate_fine(field / f"v{k}", rois, name=f"fine-{label}.laz")
            chosen.append([str(fine)])
            action(f"{label}: add the fine scans", do("Epoch", "Add fine scans to the selected epoch…"))
            action(f"{label}: check before leaving", do("Epoch", "Check the fine scans before leaving"))
            dlg = win.commands.check_dialog
            short = [t.reflector for t in dlg.result.short] if dlg is not None else []
            print(f"    the check asks to re-scan: {', '.join(short) or 'nothing'}")
            rescans += len(short)
            if dlg is not None:
                dlg.close()
            action(f"{label}: process" + (" anyway" if short else ""), do("Epoch", "Process"))
        for view in ("displacements", "map", "fine", "analysis"):
            action(f"tab {view}", lambda view=view: win.state.request_view(view))
        win.state.select(epoch="v1", reflector="M3")
        action("inspect M3's fine scan", do("Epoch", "Inspect the selected target's fine scan"))
        win.state.request_view("cloud")
        wait(200)
        cv = win.cloud_view
        cv.mode.setCurrentIndex(0)
        action("3-D: show the scan", cv.show_btn.click)
        cv.mode.setCurrentIndex(1)
        action("3-D: show the change against the baseline", cv.show_btn.click)
        chosen.append(tmp / "report.pdf")
        action("write the report", do("Reports", "Write report (PDF)…"))
        action("reload the campaign", do("View", "Reload campaign"))
        ticks.timer.stop()
        if errors:
            print("errors shown:", errors)
        worst = max(rows, key=lambda r: r[1])
        print(f"  RESULT: longest gap {worst[1] * 1000:.0f} ms ({worst[0]}); target {TARGET_S * 1000:.0f} ms; "
              f"{sum(g > TARGET_S for _, g, _ in rows)} of {len(rows)} actions above it")
        figures(actions=len(rows), longest_gap_ms=worst[1] * 1000, over_target=sum(g > TARGET_S for _, g, _ in rows),
                errors=len(errors), rescans_asked=rescans, points_per_coarse_scan=_points(field / "v0" / "coarse.laz"))
        table = "| action | longest gap (ms) | action took (s) |\n|---|---:|---:|\n" + "".join(
            f"| {n} | {g * 1000:.0f} | {d:.1f} |\n" for n, g, d in rows)
        write_figure("bench_gui_latency", table, notes=(
            f"A {TICK_MS} ms timer on the interface thread; longest gap between two of its ticks from an action's "
            f"start until its result is drawn (plus 0.3 s). Target: {TARGET_S * 1000:.0f} ms. Xvfb, software "
            "OpenGL; coarse scans at {step_deg}°.".replace("{step_deg}", str(step_deg))))
        win.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _points(path: Path) -> int:
    import laspy

    with laspy.open(path) as f:
        return int(f.header.point_count)


if __name__ == "__main__":
    _small, _args = small_mode()
    if not os.environ.get("DISPLAY") and shutil.which("xvfb-run") and not os.environ.get("_BENCH_XVFB"):
        env = {**os.environ, "QT_QPA_PLATFORM": "xcb", "_BENCH_XVFB": "1", "MPLBACKEND": "Agg"}
        sys.exit(subprocess.call(["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", sys.executable, __file__,
                                  *sys.argv[1:]], env=env))
    os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
    run(0.12 if _small else 0.06, _small)

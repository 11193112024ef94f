"""The main window: campaign tree, central views, details panel, menus, toolbar and a status bar with
progress and cancel. Every action that changes the campaign runs as a background job."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

from PySide6.QtCore import QSettings, Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (QDockWidget, QFileDialog, QHBoxLayout, QInputDialog, QLabel, QListWidget,
                               QMainWindow, QMessageBox, QProgressBar, QPushButton, QStackedWidget, QTabWidget,
                               QVBoxLayout, QWidget)

from app.gui import actions
from app.gui.campaign_tree import CampaignTree
from app.gui.details import DetailsPanel, campaign_html, epoch_html, reflector_html, series_html
from app.gui.dialogs import AddEpochDialog, ImportCameraDialog, NewCampaignDialog, ask_save_path, show_error
from app.gui.session import CampaignSession
from app.gui.views.camera_view import CameraView
from app.gui.views.cloud_view import CloudView
from app.gui.views.displacement_view import DisplacementView
from app.gui.views.fine_view import FineScanView
from app.gui.views.map_view import MapView
from app.gui.worker import JobRunner
from lidar.errors import SurveyError

MAX_RECENT = 8


def settings() -> QSettings:
    return QSettings(QSettings.IniFormat, QSettings.UserScope, "BridgeSurvey", "bridgesurvey-gui")


class WelcomePage(QWidget):
    """Shown without a campaign: open the demo, open or create a campaign, or a recent one."""

    def __init__(self, window: "MainWindow"):
        super().__init__()
        lay = QVBoxLayout(self)
        title = QLabel("<h2>BridgeSurvey</h2><p>Long-term bridge displacement from weekly laser scans of "
                       "reflector targets, cross-checked with a dual-camera system.</p>")
        title.setWordWrap(True)
        lay.addWidget(title)
        row = QHBoxLayout()
        for text, slot in (("Open the demo campaign", window.open_demo), ("Open campaign…", window.open_dialog),
                           ("New campaign…", window.new_campaign)):
            b = QPushButton(text)
            b.clicked.connect(slot)
            row.addWidget(b)
        row.addStretch(1)
        lay.addLayout(row)
        lay.addWidget(QLabel("Recent campaigns (double-click to open):"))
        self.recent = QListWidget()
        self.recent.itemDoubleClicked.connect(lambda it: window.open_campaign(it.text()))
        lay.addWidget(self.recent, 1)

    def set_recent(self, paths) -> None:
        self.recent.clear()
        self.recent.addItems(list(paths))


class MainWindow(QMainWindow):
    def __init__(self, *, demo_dir: Optional[str] = None):
        super().__init__()
        self.setWindowTitle("BridgeSurvey")
        self.demo_dir = Path(demo_dir) if demo_dir else Path.cwd() / "demo-campaign"
        self.session: Optional[CampaignSession] = None
        self.jobs = JobRunner(self)
        self._build_views()
        self._build_docks()
        self._build_status()
        self._build_actions()
        self._connect()
        self.resize(1400, 900)
        s = settings()
        if s.value("geometry") is not None:
            self.restoreGeometry(s.value("geometry"))
            self.restoreState(s.value("state"))
        self.welcome.set_recent(self.recent())
        self._set_campaign_enabled(False)

    # ------------------------------------------------------------------ construction
    def _build_views(self) -> None:
        self.tabs = QTabWidget()
        self.displacements = DisplacementView()
        self.map_view = MapView()
        self.fine_view = FineScanView()
        self.cloud_view = CloudView()
        self.camera_view = CameraView()
        for w, name in ((self.displacements, "Displacements"), (self.map_view, "Reflectance map"),
                        (self.fine_view, "Fine scan"), (self.cloud_view, "3-D"), (self.camera_view, "Camera")):
            self.tabs.addTab(w, name)
        self.welcome = WelcomePage(self)
        self.stack = QStackedWidget()
        self.stack.addWidget(self.welcome)
        self.stack.addWidget(self.tabs)
        self.setCentralWidget(self.stack)

    def _build_docks(self) -> None:
        self.tree = CampaignTree()
        self.tree.setMinimumWidth(300)
        d = QDockWidget("Campaign", self)
        d.setObjectName("campaign-dock")
        d.setWidget(self.tree)
        self.addDockWidget(Qt.LeftDockWidgetArea, d)
        self.tree_dock = d
        self.details = DetailsPanel()
        d = QDockWidget("Details", self)
        d.setObjectName("details-dock")
        d.setWidget(self.details)
        self.addDockWidget(Qt.RightDockWidgetArea, d)
        self.details_dock = d

    def _build_status(self) -> None:
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setMaximumWidth(260)
        self.progress.hide()
        self.cancel_btn = QPushButton("Cancel")
        self.cancel_btn.hide()
        self.cancel_btn.clicked.connect(self.jobs.cancel)
        self.statusBar().addPermanentWidget(self.progress)
        self.statusBar().addPermanentWidget(self.cancel_btn)

    def _action(self, menu, text: str, slot: Callable, shortcut=None, needs_campaign: bool = True) -> QAction:
        a = QAction(text, self)
        a.triggered.connect(lambda _checked=False: slot())
        if shortcut:
            a.setShortcut(QKeySequence(shortcut))
        menu.addAction(a)
        if needs_campaign:
            self._campaign_actions.append(a)
        return a

    def _build_actions(self) -> None:
        self._campaign_actions: list[QAction] = []
        mb = self.menuBar()
        m = mb.addMenu("&File")
        self.act_new = self._action(m, "&New campaign…", self.new_campaign, "Ctrl+N", False)
        self.act_open = self._action(m, "&Open campaign…", self.open_dialog, "Ctrl+O", False)
        self._action(m, "Open the &demo campaign", self.open_demo, None, False)
        self.recent_menu = m.addMenu("Open &recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent_menu)
        self._action(m, "&Close campaign", self.close_campaign)
        m.addSeparator()
        self._action(m, "&Quit", self.close, "Ctrl+Q", False)
        m = mb.addMenu("C&ampaign")
        self._action(m, "Set &limit…", self.set_limit)
        self._action(m, "&Retire the selected reflector…", self.retire_reflector)
        self._action(m, "Re&place the selected reflector…", self.replace_reflector)
        self._action(m, "Processing &parameter…", self.set_parameter)
        m = mb.addMenu("&Epoch")
        self.act_add_epoch = self._action(m, "&Add epoch…", self.add_epoch, "Ctrl+E")
        self._action(m, "Add &fine scans to the selected epoch…", self.add_fine)
        self._action(m, "&Plan the selected epoch", self.plan_selected)
        self.act_process = self._action(m, "P&rocess", self.process, "F5")
        self._action(m, "&Inspect the selected target's fine scan", self.show_fine)
        m = mb.addMenu("&Camera")
        self._action(m, "&Import series…", self.import_camera)
        self._action(m, "&Cross-validate with LiDAR", self.crossval)
        m = mb.addMenu("&Reports")
        self._action(m, "Export &displacements (CSV)…", self.export_csv)
        self._action(m, "Export &workbook (XLSX)…", self.export_xlsx)
        self.act_report = self._action(m, "Write &report (PDF)…", self.write_report, "Ctrl+R")
        m = mb.addMenu("&View")
        m.addAction(self.tree_dock.toggleViewAction())
        m.addAction(self.details_dock.toggleViewAction())
        self._action(m, "Re&load campaign", self.refresh, "Ctrl+L")
        m = mb.addMenu("&Help")
        self._action(m, "&About", lambda: QMessageBox.about(
            self, "BridgeSurvey", "BridgeSurvey: long-term bridge displacement from temporarily installed "
                                  "terrestrial LiDAR and a dual-camera system."), None, False)
        tb = self.addToolBar("Main")
        tb.setObjectName("main-toolbar")
        for a in (self.act_open, self.act_add_epoch, self.act_process, self.act_report):
            tb.addAction(a)

    def _connect(self) -> None:
        self.jobs.started.connect(self._job_started)
        self.jobs.progress.connect(self._job_progress)
        self.jobs.finished.connect(self._job_finished)
        self.jobs.error.connect(self._job_error)
        self.tree.picked.connect(self._tree_picked)
        self.tree.activated_item.connect(self._tree_activated)
        self.displacements.epochPicked.connect(lambda lab: self.session and self.session.select(epoch=lab))
        self.map_view.saveRequested.connect(self.save_plan)
        self.map_view.exportRequested.connect(self.export_plan)
        self.map_view.addRequested.connect(self.add_window)
        self.map_view.reflectorPicked.connect(lambda rid: self.session and self.session.select(reflector=rid))
        self.cloud_view.loadRequested.connect(self.show_cloud)
        self.cloud_view.targetPicked.connect(lambda rid: self.session and self.session.select(reflector=rid))
        self.camera_view.crossvalRequested.connect(self.crossval)
        self.camera_view.importRequested.connect(self.import_camera)
        self.tabs.currentChanged.connect(self._tab_changed)

    # ------------------------------------------------------------------ campaigns
    def recent(self) -> list[str]:
        v = settings().value("recent", [])
        return [p for p in ([v] if isinstance(v, str) else (v or [])) if p]

    def _remember(self, folder: Path) -> None:
        paths = [str(folder)] + [p for p in self.recent() if p != str(folder)]
        settings().setValue("recent", paths[:MAX_RECENT])
        self.welcome.set_recent(paths[:MAX_RECENT])

    def _fill_recent_menu(self) -> None:
        self.recent_menu.clear()
        for p in self.recent():
            a = self.recent_menu.addAction(p)
            a.triggered.connect(lambda _c=False, p=p: self.open_campaign(p))

    def open_campaign(self, folder) -> bool:
        try:
            session = CampaignSession(folder, self)
        except SurveyError as exc:
            show_error(self, "Open campaign", str(exc))
            return False
        self.session = session
        session.changed.connect(self.refresh)
        session.selectionChanged.connect(self._selection_changed)
        self._remember(session.folder)
        self.setWindowTitle(f"BridgeSurvey — {session.name}")
        self.stack.setCurrentWidget(self.tabs)
        self._set_campaign_enabled(True)
        self.refresh()
        return True

    def close_campaign(self) -> None:
        self.session = None
        self.tree.clear()
        self.details.clear()
        self.setWindowTitle("BridgeSurvey")
        self.stack.setCurrentWidget(self.welcome)
        self._set_campaign_enabled(False)

    def _set_campaign_enabled(self, on: bool) -> None:
        for a in self._campaign_actions:
            a.setEnabled(on)

    def open_dialog(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Open campaign folder")
        if folder:
            self.open_campaign(folder)

    def open_demo(self) -> None:
        from projects.store import DB_NAME

        if (self.demo_dir / DB_NAME).exists():
            self.open_campaign(self.demo_dir)
            return
        if QMessageBox.question(self, "Demo campaign", f"The demo campaign is not built yet. Build it in "
                                f"{self.demo_dir}? (52 simulated weekly visits, a few minutes)") != QMessageBox.Yes:
            return
        self.run_job("Building the demo campaign", lambda p: actions.build_demo(self.demo_dir, p),
                     lambda _r: self.open_campaign(self.demo_dir))

    def new_campaign(self) -> None:
        dlg = NewCampaignDialog(self)
        if dlg.exec() != NewCampaignDialog.Accepted:
            return
        v = dlg.values()
        try:
            folder = actions.create_campaign(**v)
        except SurveyError as exc:
            show_error(self, "New campaign", str(exc))
            return
        self.open_campaign(folder)

    # ------------------------------------------------------------------ jobs
    def run_job(self, title: str, fn: Callable, on_done: Optional[Callable] = None) -> bool:
        if not self.jobs.run(title, fn, on_done):
            show_error(self, title, "Another task is still running; wait for it or cancel it first.")
            return False
        return True

    def _job_started(self, title: str) -> None:
        self.progress.setValue(0)
        self.progress.show()
        self.cancel_btn.show()
        self.statusBar().showMessage(title + "…")

    def _job_progress(self, fraction: float, message: str) -> None:
        self.progress.setValue(int(fraction * 1000))
        if message:
            self.statusBar().showMessage(message)

    def _job_finished(self, title: str, ok: bool) -> None:
        self.progress.hide()
        self.cancel_btn.hide()
        if ok:
            self.statusBar().showMessage(f"{title}: done", 8000)

    def _job_error(self, title: str, message: str, kind: str) -> None:
        if kind == "cancelled":
            self.statusBar().showMessage(f"{title}: cancelled", 8000)
        else:
            show_error(self, title, message)

    def _changed(self, _result=None) -> None:
        if self.session is not None:
            self.session.changed.emit()

    # ------------------------------------------------------------------ refresh and selection
    def refresh(self) -> None:
        if self.session is None:
            return
        from projects.camera import series_rows
        from projects.overview import campaign_status

        try:
            with self.session.read() as c:
                status = campaign_status(c)
                reflectors = c.reflectors()
                series = series_rows(c)
                rows = c.displacement_rows()
                limits = {r["id"]: c.limit_for(r["id"]) for r in reflectors if r["grp"] == "measurement"}
        except SurveyError as exc:
            show_error(self, "Reload campaign", str(exc))
            return
        self.status_data = status
        self.tree.populate(status, reflectors, series)
        self.displacements.set_data(rows, limits)
        self._show_details()
        self._tab_changed(self.tabs.currentIndex())

    def _tree_picked(self, kind: str, key: str) -> None:
        if self.session is None:
            return
        if kind == "reflector":
            self.session.select(reflector=key)
        elif kind == "epoch":
            self.session.select(epoch=key)
        self._details_for = (kind, key)
        self._show_details()

    def _tree_activated(self, kind: str, key: str) -> None:
        if kind == "epoch":
            self.tabs.setCurrentWidget(self.map_view)
        elif kind == "reflector":
            self.tabs.setCurrentWidget(self.displacements)
        elif kind == "series":
            self.tabs.setCurrentWidget(self.camera_view)

    def _selection_changed(self) -> None:
        s = self.session
        if s.reflector:
            self.displacements.show_target(s.reflector)
            self.map_view.select_reflector(s.reflector)
            self.cloud_view.select_target(s.reflector)
        self.displacements.select_epoch(s.epoch)
        kind_key = ("reflector", s.reflector) if getattr(self, "_details_for", ("", ""))[0] == "reflector" \
            else ("epoch", s.epoch)
        if kind_key[1]:
            self.tree.select_key(*kind_key)
        self._tab_changed(self.tabs.currentIndex())

    def _show_details(self) -> None:
        if self.session is None:
            return
        kind, key = getattr(self, "_details_for", ("campaign", ""))
        from projects.camera import series_rows

        try:
            with self.session.read() as c:
                if kind == "reflector":
                    text = reflector_html(c, key)
                elif kind == "epoch":
                    text = epoch_html(c, key)
                elif kind == "series":
                    text = series_html(next(r for r in series_rows(c) if r["name"] == key))
                else:
                    text = campaign_html(c, self.status_data)
        except (SurveyError, StopIteration) as exc:
            text = f"<p>{exc}</p>"
        self.details.setHtml(text)

    def _tab_changed(self, _index: int) -> None:
        """Load what the visible view needs for the current selection (lazily, views that read scans
        load on request)."""
        if self.session is None:
            return
        w = self.tabs.currentWidget()
        if w is self.map_view:
            self._load_map()
        elif w is self.camera_view:
            self._load_camera()

    # ------------------------------------------------------------------ map and plan
    def _load_map(self) -> None:
        label = self.session.epoch or self._last_epoch()
        if label is None:
            self.map_view.show_message("No epoch yet: add one (Epoch ▸ Add epoch…).")
            return
        if self.map_view.plan is not None and getattr(self.map_view, "label", None) == label and self.map_view.dirty:
            return  # keep unsaved edits
        from lidar.plan import ScanPlan

        with self.session.read() as c:
            preview = c.map_preview(label)
            row = c.plan_row(label)
        if preview is None:
            self.map_view.show_message(f"Epoch {label} has not been planned yet: Epoch ▸ Plan, or Process.")
            return
        self.map_view.label = label
        self.map_view.load(label, preview, None if row is None else ScanPlan.from_json(json.loads(row["json"])))
        if self.session.reflector:
            self.map_view.select_reflector(self.session.reflector)

    def _last_epoch(self) -> Optional[str]:
        eps = getattr(self, "status_data", {}).get("epochs", [])
        return eps[-1]["epoch"] if eps else None

    def save_plan(self, plan) -> None:
        label = getattr(self.map_view, "label", None)
        if plan is None or label is None:
            return

        def done(_r):
            self.map_view.dirty = False
            self._changed()

        self.run_job(f"Saving the plan of {label}", lambda p: actions.save_plan(self.session, label, plan), done)

    def export_plan(self, plan) -> None:
        if plan is None:
            return
        path = ask_save_path(self, "Export plan", f"plan-{plan.epoch}.json", "Plan (*.json)")
        if path is not None:
            try:
                plan.save(path)
                self.statusBar().showMessage(f"plan written to {path}", 8000)
            except (SurveyError, OSError) as exc:
                show_error(self, "Export plan", str(exc))

    def add_window(self, rect) -> None:
        """A window drawn on the map: ask which target it is for and add it with steps for that target."""
        self.map_view.draw_btn.setChecked(False)
        if self.map_view.plan is None:
            return
        with self.session.read() as c:
            refl = {r["id"]: r for r in c.reflectors() if not r["retired"]}
        taken = {it.roi.reflector for it in self.map_view.items}
        free = [rid for rid in refl if rid not in taken]
        if not free:
            show_error(self, "Add window", "Every reflector has a window already; move or resize it instead.")
            return
        rid, ok = QInputDialog.getItem(self, "Add window", "Reflector:", free, 0, False)
        if not ok:
            return
        try:
            roi = actions.window_from_rect(self.map_view, rect, rid, refl[rid])
        except SurveyError as exc:
            show_error(self, "Add window", str(exc))
            return
        self.map_view.add_roi(roi)

    # ------------------------------------------------------------------ epoch work
    def add_epoch(self) -> None:
        dlg = AddEpochDialog(self)
        if dlg.exec() != AddEpochDialog.Accepted:
            return
        v = dlg.values()
        self.run_job(f"Importing epoch {v['label']}", lambda p: actions.add_epoch(self.session, v, p),
                     lambda label: (self._changed(), self.session.select(epoch=label)))

    def add_fine(self) -> None:
        label = self.session.epoch
        if not label:
            show_error(self, "Add fine scans", "Select an epoch in the campaign tree first.")
            return
        from app.gui.dialogs import SCAN_FILTER

        paths, _ = QFileDialog.getOpenFileNames(self, f"Fine scans of {label}", "", SCAN_FILTER)
        if paths:
            self.run_job(f"Importing fine scans of {label}", lambda p: actions.add_fine(self.session, label, paths, p),
                         self._changed)

    def plan_selected(self) -> None:
        label = self.session.epoch or self._last_epoch()
        if label:
            self.run_job(f"Planning {label}", lambda p: actions.plan(self.session, label, p), self._changed)

    def process(self) -> None:
        self.run_job("Processing", lambda p: actions.process(self.session, p), self._processed)

    def _processed(self, summary) -> None:
        self._changed()
        if summary.failed:
            show_error(self, "Processing", "\n".join(f"{o.epoch}: {o.message}" for o in summary.failed))

    def show_fine(self) -> None:
        s = self.session
        label, rid = s.epoch or self._last_epoch(), s.reflector
        if not label or not rid:
            self.fine_view.show_message("Select an epoch and a target (tree, map or 3-D view) first.")
            self.tabs.setCurrentWidget(self.fine_view)
            return
        self.tabs.setCurrentWidget(self.fine_view)
        self.run_job(f"Reading the window of {rid} in {label}", lambda p: actions.inspect(s, label, rid, p),
                     self.fine_view.set_inspection)

    def show_cloud(self, mode: str) -> None:
        s = self.session
        label = s.epoch or self._last_epoch()
        if not label:
            return
        self.cloud_view.mode.setCurrentIndex(0 if mode == "intensity" else 1)
        if mode == "intensity":
            self.run_job(f"Loading the scan of {label}", lambda p: actions.epoch_cloud(s, label, p),
                         self.cloud_view.set_cloud)
        else:
            self.run_job(f"Comparing {label} with the baseline", lambda p: actions.change_cloud(s, label, p),
                         lambda r: (self.cloud_view.set_cloud(r), self._changed()))

    # ------------------------------------------------------------------ campaign settings
    def _ask(self, title: str, label: str, text: str = "") -> Optional[str]:
        value, ok = QInputDialog.getText(self, title, label, text=text)
        return value.strip() if ok and value.strip() else None

    def _quick(self, title: str, fn: Callable) -> None:
        """Small changes run in the GUI thread; errors are shown, the campaign is left as it was."""
        try:
            fn()
        except SurveyError as exc:
            show_error(self, title, str(exc))
            return
        self._changed()

    def set_limit(self) -> None:
        rid = self.session.reflector or "*"
        rule = self._ask("Set limit", f"Limit rule for {'every measurement target' if rid == '*' else rid} "
                                      "(kr-rail:0-200, abs:10,15 mm or span:1000,500):", "kr-rail:0-200")
        if rule:
            self._quick("Set limit", lambda: actions.set_limit(self.session, rid, rule))

    def retire_reflector(self) -> None:
        rid = self.session.reflector
        if not rid:
            show_error(self, "Retire reflector", "Select a reflector in the campaign tree first.")
            return
        when = self._ask("Retire reflector", f"Retire {rid} from (ISO date):")
        if when:
            self._quick("Retire reflector", lambda: actions.retire_reflector(self.session, rid, when))

    def replace_reflector(self) -> None:
        rid = self.session.reflector
        if not rid:
            show_error(self, "Replace reflector", "Select a reflector in the campaign tree first.")
            return
        new = self._ask("Replace reflector", f"New id of the target replacing {rid}:", f"{rid}b")
        when = new and self._ask("Replace reflector", f"{new} replaces {rid} from (ISO date):")
        if new and when:
            self._quick("Replace reflector", lambda: actions.replace_reflector(self.session, rid, new, when))

    def set_parameter(self) -> None:
        from projects.processing import DEFAULTS, parameters

        with self.session.read() as c:
            current = parameters(c)
        keys = list(DEFAULTS) + ["baseline"]
        key, ok = QInputDialog.getItem(self, "Processing parameter", "Parameter:", keys, 0, False)
        if not ok:
            return
        text = self._ask("Processing parameter", f"New value of {key} (now {current.get(key)}):")
        if text is not None:
            self._quick("Processing parameter", lambda: actions.set_parameter(self.session, key, text))

    # ------------------------------------------------------------------ camera
    def _load_camera(self) -> None:
        from projects.camera import crossval_summaries, load_series
        from vision.crossval import CrossValidation

        with self.session.read() as c:
            sums = crossval_summaries(c)
            cam = load_series(c, sums[0]["series"])[1] if sums else None
        if sums:
            self.camera_view.set_result(CrossValidation.from_json(sums[0]), cam)
        else:
            self.camera_view.show_message("No cross-validation yet: import a camera series, then Camera ▸ "
                                          "Cross-validate with LiDAR.")

    def import_camera(self) -> None:
        from projects.camera import midspan_reflector

        with self.session.read() as c:
            meas = [r["id"] for r in c.reflectors() if r["grp"] == "measurement" and not r["retired"]]
            try:
                default = midspan_reflector(c)
            except SurveyError:
                default = None
        dlg = ImportCameraDialog(meas, default, self)
        if dlg.exec() != ImportCameraDialog.Accepted:
            return
        v = dlg.values()
        self.run_job("Importing the camera series", lambda p: actions.import_camera(self.session, v, p),
                     self._changed)

    def crossval(self) -> None:
        def done(_r):
            self._changed()
            self.tabs.setCurrentWidget(self.camera_view)
            self._load_camera()

        self.run_job("Cross-validating", lambda p: actions.crossval(self.session, p), done)

    # ------------------------------------------------------------------ exports
    def export_csv(self) -> None:
        path = ask_save_path(self, "Export displacements", "displacements.csv", "CSV (*.csv)")
        if path is not None:
            self.run_job("Exporting displacements", lambda p: actions.export_csv(self.session, path))

    def export_xlsx(self) -> None:
        path = ask_save_path(self, "Export workbook", "campaign.xlsx", "Excel workbook (*.xlsx)")
        if path is not None:
            self.run_job("Exporting the workbook", lambda p: actions.export_xlsx(self.session, path))

    def write_report(self) -> None:
        path = ask_save_path(self, "Write report", "report.pdf", "PDF (*.pdf)")
        if path is not None:
            self.run_job("Writing the report", lambda p: actions.report(self.session, path, p),
                         lambda r: self.statusBar().showMessage(f"report written to {r}", 10000))

    # ------------------------------------------------------------------ shutdown
    def closeEvent(self, event) -> None:
        if self.jobs.busy:
            if QMessageBox.question(self, "Quit", "A task is still running. Cancel it and quit?") != QMessageBox.Yes:
                event.ignore()
                return
            self.jobs.cancel()
            self.jobs.wait(30_000)
        s = settings()
        s.setValue("geometry", self.saveGeometry())
        s.setValue("state", self.saveState())
        self.cloud_view.close_plotter()
        super().closeEvent(event)

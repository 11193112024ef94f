"""The main window: campaign tree, central views, details panel, menus, toolbar and a status bar with
progress and cancel. Every action that changes the campaign runs as a background job."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional

from PySide6.QtCore import QSettings, Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (QDockWidget, QFileDialog, QHBoxLayout, QLabel, QListWidget,
                               QMainWindow, QMessageBox, QProgressBar, QPushButton, QStackedWidget, QTabWidget,
                               QVBoxLayout, QWidget)

from app.gui import actions
from app.gui.campaign_tree import CampaignTree
from app.gui.commands import Commands
from app.gui.details import DetailsPanel
from app.gui.html import campaign_html, epoch_html, reflector_html, series_html
from app.gui.dialogs import NewCampaignDialog, show_error
from app.gui.session import CampaignSession
from app.gui.views.camera_view import CameraView
from app.gui.views.cloud_view import CloudView
from app.gui.views.displacement_view import DisplacementView
from app.gui.views.fine_view import FineScanView
from app.gui.views.map_view import MapView
from app.gui.views.analysis_view import AnalysisView
from app.gui.views.stations_view import StationsView
from app.gui.worker import JobRunner
from common.errors import SurveyError

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
        self.status_data: dict = {"epochs": []}          # projects.overview.campaign_status of the last refresh
        self._details_for: tuple[str, str] = ("campaign", "")  # what the details panel shows
        self.jobs = JobRunner(self)
        self.commands = Commands(self)
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
        self.stations_view = StationsView()
        self.analysis_view = AnalysisView()
        for w, name in ((self.displacements, "Displacements"), (self.map_view, "Reflectance map"),
                        (self.fine_view, "Fine scan"), (self.cloud_view, "3-D"), (self.camera_view, "Camera"),
                        (self.stations_view, "Stations"), (self.analysis_view, "Analysis")):
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
        self._action(m, "&Fleet (many bridges)…", self.open_fleet, None, False)
        self.recent_menu = m.addMenu("Open &recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent_menu)
        self._action(m, "&Close campaign", self.close_campaign)
        m.addSeparator()
        self._action(m, "&Quit", self.close, "Ctrl+Q", False)
        m = mb.addMenu("C&ampaign")
        self._action(m, "Set &limit…", self.commands.set_limit)
        self._action(m, "&Retire the selected reflector…", self.commands.retire_reflector)
        self._action(m, "Re&place the selected reflector…", self.commands.replace_reflector)
        self._action(m, "Processing &parameter…", self.commands.set_parameter)
        self._action(m, "&Scanner…", self.commands.choose_scanner)
        self._action(m, "&Where to stand…", self.commands.evaluate_stations)
        m = mb.addMenu("&Epoch")
        self.act_add_epoch = self._action(m, "&Add epoch…", self.commands.add_epoch, "Ctrl+E")
        self._action(m, "Add &fine scans to the selected epoch…", self.commands.add_fine)
        self._action(m, "&Plan the selected epoch", self.commands.plan_selected)
        self._action(m, "Field &sheet of the selected epoch (PDF)…", self.commands.field_sheet)
        self._action(m, "&Check the fine scans before leaving", self.commands.check_selected)
        self.act_process = self._action(m, "P&rocess", self.commands.process, "F5")
        self._action(m, "&Inspect the selected target's fine scan", self.commands.show_fine)
        m = mb.addMenu("&Camera")
        self._action(m, "&Import series…", self.commands.import_camera)
        self._action(m, "&Cross-validate with LiDAR", self.commands.crossval)
        m = mb.addMenu("&Reports")
        self._action(m, "Export &displacements (CSV)…", self.commands.export_csv)
        self._action(m, "Export &workbook (XLSX)…", self.commands.export_xlsx)
        self.act_report = self._action(m, "Write &report (PDF)…", self.commands.write_report, "Ctrl+R")
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
        self.map_view.saveRequested.connect(self.commands.save_plan)
        self.map_view.exportRequested.connect(self.commands.export_plan)
        self.map_view.addRequested.connect(self.commands.add_window)
        self.map_view.reflectorPicked.connect(lambda rid: self.session and self.session.select(reflector=rid))
        self.cloud_view.loadRequested.connect(self.commands.show_cloud)
        self.cloud_view.targetPicked.connect(lambda rid: self.session and self.session.select(reflector=rid))
        self.camera_view.crossvalRequested.connect(self.commands.crossval)
        self.camera_view.importRequested.connect(self.commands.import_camera)
        self.stations_view.evaluateRequested.connect(self.commands.evaluate_stations)
        self.analysis_view.runRequested.connect(self.commands.run_analysis)
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

    def open_fleet(self, folder: Optional[str] = None) -> None:
        """List every campaign under a folder (worst state first) and open any of them."""
        from app.gui import actions
        from app.gui.views.fleet_view import FleetView

        folder = folder or QFileDialog.getExistingDirectory(self, "Folder holding the campaigns")
        if not folder:
            return

        def done(status):
            self.fleet_view = FleetView(self)
            self.fleet_view.openRequested.connect(lambda f: (self.open_campaign(f), self.fleet_view.close()))
            self.fleet_view.show_status(status)
            self.fleet_view.show()

        self.run_job(f"Reading the campaigns under {folder}", lambda p: actions.fleet_status(folder), done)

    def open_dialog(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Open campaign folder")
        if folder:
            self.open_campaign(folder)

    def open_demo(self) -> None:
        from projects.store.campaign import DB_NAME

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
        from projects.series.camera import series_records
        from projects.series.context import plot_context
        from projects.store.history import histories
        from projects.results.state import campaign_status

        try:
            with self.session.read() as c:
                status = campaign_status(c)
                reflectors = c.reflectors()
                series = series_records(c)
                hist = histories(c)
                context = plot_context(c)
        except SurveyError as exc:
            show_error(self, "Reload campaign", str(exc))
            return
        self.status_data = status
        self.tree.populate(status, reflectors, series)
        self.displacements.set_data(hist, context)
        self._show_details()
        self._tab_changed(self.tabs.currentIndex(), reload=True)

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
        kind_key = ("reflector", s.reflector) if self._details_for[0] == "reflector" \
            else ("epoch", s.epoch)
        if kind_key[1]:
            self.tree.select_key(*kind_key)
        self._tab_changed(self.tabs.currentIndex())

    def _show_details(self) -> None:
        if self.session is None:
            return
        kind, key = self._details_for
        from projects.series.camera import series_records

        try:
            with self.session.read() as c:
                if kind == "reflector":
                    text = reflector_html(c, key)
                elif kind == "epoch":
                    text = epoch_html(c, key)
                elif kind == "series":
                    text = series_html(next(r for r in series_records(c) if r.name == key))
                else:
                    text = campaign_html(c, self.status_data)
        except (SurveyError, StopIteration) as exc:
            text = f"<p>{exc}</p>"
        self.details.setHtml(text)

    def _tab_changed(self, _index: int, *, reload: bool = False) -> None:
        """Load what the visible view needs for the current selection (lazily, views that read scans
        load on request); ``reload`` after the campaign changed."""
        if self.session is None:
            return
        w = self.tabs.currentWidget()
        if w is self.map_view:
            self.commands._load_map(reload=reload)
        elif w is self.camera_view:
            self.commands._load_camera()

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

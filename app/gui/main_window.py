"""The main window: campaign tree, central views, details panel, menus, toolbar and a status bar with
progress and cancel.

The window builds the widgets and wires them to the application's Qt-free state
(:class:`app.gui.state.app_state.AppState`): the views subscribe to its events and draw what they
carry, the user's gestures go to the state (selection) or to the commands (:class:`app.gui.commands.Commands`,
which run the work as background jobs). The window itself pushes no data into any view.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6.QtCore import QSettings, Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QDockWidget,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QMainWindow,
    QMessageBox,
    QProgressBar,
    QPushButton,
    QStackedWidget,
    QTabWidget,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from app.gui.campaign_tree import CampaignTree
from app.gui.commands import Commands
from app.gui.details import DetailsPanel
from app.gui.dialogs import ask_folder, show_error
from app.gui.state.app_state import AppState
from app.gui.state.folders import LastFolders
from app.gui.views.analysis_view import AnalysisView
from app.gui.views.camera_view import CameraView
from app.gui.views.cloud_view import CloudView
from app.gui.views.displacement_view import DisplacementView
from app.gui.views.fine_view import FineScanView
from app.gui.views.map_view import MapView
from app.gui.views.stations_view import StationsView
from app.gui.worker import JobRunner
from projects.store.campaign import DB_NAME

MAX_RECENT = 8
#: The smallest screen the window is laid out for (a common laptop); a test keeps every tab within it.
SMALL_SCREEN = (1366, 768)


def settings() -> QSettings:
    return QSettings(QSettings.IniFormat, QSettings.UserScope, "BridgeSurvey", "bridgesurvey-gui")


class SettingsStore:
    """QSettings as the plain mapping :class:`app.gui.state.folders.LastFolders` keeps its folders in."""

    def get(self, key: str, default=None):
        v = settings().value(key, default)
        return v if isinstance(v, str) else default

    def __getitem__(self, key: str) -> str:
        v = self.get(key)
        if v is None:
            raise KeyError(key)
        return v

    def __setitem__(self, key: str, value: str) -> None:
        settings().setValue(key, value)


class WelcomePage(QWidget):
    """Shown without a campaign: open the demo, open or create a campaign, or a recent one."""

    def __init__(self, window: MainWindow):
        super().__init__()
        lay = QVBoxLayout(self)
        title = QLabel("<h2>BridgeSurvey</h2><p>Long-term bridge displacement from weekly laser scans of "
                       "reflector targets, cross-checked with a dual-camera system.</p>")
        title.setWordWrap(True)
        lay.addWidget(title)
        row = QHBoxLayout()
        for text, slot in (("Open the demo campaign", window.open_demo), ("Open campaign…", window.open_dialog),
                           ("New campaign…", window.commands.new_campaign)):
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
    #: The tabs, by the view names of :data:`app.gui.state.app_state.VIEWS`.
    TABS = (("displacements", "Displacements"), ("map", "Reflectance map"), ("fine", "Fine scan"), ("cloud", "3-D"),
            ("camera", "Camera"), ("stations", "Stations"), ("analysis", "Analysis"))

    def __init__(self, *, demo_dir: str | None = None):
        super().__init__()
        self.setWindowTitle("BridgeSurvey")
        self.demo_dir = Path(demo_dir) if demo_dir else Path.cwd() / "demo-campaign"
        self.state = AppState()
        self.folders = LastFolders(SettingsStore())
        self.jobs = JobRunner(self)
        self.commands = Commands(self)
        self._build_views()
        self._build_docks()
        self._build_status()
        self._build_actions()
        self._wire()
        self.resize(1366, 768)
        s = settings()
        if s.value("geometry") is not None:
            self.restoreGeometry(s.value("geometry"))
            self.restoreState(s.value("state"))
        self.welcome.set_recent(self.recent())
        self._set_campaign_enabled(False)

    # ------------------------------------------------------------------ construction
    def _build_views(self) -> None:
        self.tabs = QTabWidget()
        self.tabs.setUsesScrollButtons(True)
        self.tabs.setElideMode(Qt.ElideNone)
        self.displacements = DisplacementView()
        self.map_view = MapView(self.state.map)
        self.fine_view = FineScanView()
        self.cloud_view = CloudView()
        self.camera_view = CameraView()
        self.stations_view = StationsView()
        self.analysis_view = AnalysisView()
        self.views = {"displacements": self.displacements, "map": self.map_view, "fine": self.fine_view,
                      "cloud": self.cloud_view, "camera": self.camera_view, "stations": self.stations_view,
                      "analysis": self.analysis_view}
        for name, title in self.TABS:
            self.tabs.addTab(self.views[name], title)
        self.welcome = WelcomePage(self)
        self.stack = QStackedWidget()
        self.stack.addWidget(self.welcome)
        self.stack.addWidget(self.tabs)
        self.setCentralWidget(self.stack)

    def _build_docks(self) -> None:
        self.tree = CampaignTree()
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
        self.resizeDocks([self.tree_dock, self.details_dock], [270, 280], Qt.Horizontal)

    def _build_status(self) -> None:
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.setMaximumWidth(200)
        self.progress.hide()
        self.cancel_btn = QPushButton("Cancel")
        self.cancel_btn.hide()
        self.zone_label = QLabel()  # the open campaign's time zone, always in sight
        self.zone_label.setToolTip("The campaign's time zone: imported times without an offset are read in it")
        self.statusBar().addPermanentWidget(self.zone_label)
        self.statusBar().addPermanentWidget(self.progress)
        self.statusBar().addPermanentWidget(self.cancel_btn)

    def _action(self, menu, text: str, slot: Callable, shortcut=None, needs_campaign: bool = True,
                tip: str = "") -> QAction:
        a = QAction(text, self)
        a.triggered.connect(lambda _checked=False: slot())
        if shortcut:
            a.setShortcut(QKeySequence(shortcut))
        if tip:
            a.setStatusTip(tip)
            a.setToolTip(tip)
        menu.addAction(a)
        if needs_campaign:
            self._campaign_actions.append(a)
        return a

    def _build_actions(self) -> None:
        self._campaign_actions: list[QAction] = []
        cmd = self.commands
        mb = self.menuBar()
        m = mb.addMenu("&File")
        self.act_new = self._action(m, "&New campaign…", cmd.new_campaign, "Ctrl+N", False)
        self.act_open = self._action(m, "&Open campaign…", self.open_dialog, "Ctrl+O", False)
        self._action(m, "Open the &demo campaign", self.open_demo, None, False)
        self._action(m, "&Fleet (many bridges)…", cmd.open_fleet, None, False)
        self.recent_menu = m.addMenu("Open &recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent_menu)
        self._action(m, "&Close campaign", self.state.close)
        m.addSeparator()
        self._action(m, "&Quit", self.close, "Ctrl+Q", False)
        m = mb.addMenu("C&ampaign")
        self._action(m, "Set &limit…", cmd.set_limit)
        self._action(m, "&Retire the selected reflector…", cmd.retire_reflector)
        self._action(m, "Re&place the selected reflector…", cmd.replace_reflector)
        self._action(m, "Processing &parameter…", cmd.set_parameter)
        self._action(m, "&Scanner…", cmd.choose_scanner)
        self._action(m, "&Where to stand…", self.stations_view.request_evaluation)
        m.addSeparator()
        self._action(m, "&Verify campaign", cmd.verify_campaign)
        self._action(m, "Re&pair campaign", cmd.repair_campaign)
        m.addSeparator()
        self._action(m, "&Archive processed scans…", cmd.archive_scans,
                     tip="Move the scans of fully processed visits to another disk, each checked; the results stay")
        self._action(m, "Restore s&cans…", cmd.restore_scans,
                     tip="Bring archived scans back into the campaign folder, each checked against its checksum")
        m = mb.addMenu("&Epoch")
        self.act_add_epoch = self._action(m, "&Add epoch…", cmd.add_epoch, "Ctrl+E",
                                          tip="Import the coarse scan of a visit (and its fine scans, if any)")
        self.act_add_fine = self._action(m, "Add &fine scans to the selected epoch…", cmd.add_fine)
        self._action(m, "Add a se&t-up to the selected epoch…", cmd.add_setup,
                     tip="Another station of the same visit (a long bridge, a pier hiding targets): its coarse scan, "
                         "planned at once; the set-ups are joined through the targets they share")
        self.act_plan = self._action(m, "&Plan the selected epoch", cmd.plan_selected, "Ctrl+P",
                                     tip="Find the targets in the coarse scan and plan a fine-scan window for each")
        self._action(m, "Field &sheet of the selected epoch (PDF)…", cmd.field_sheet)
        self.act_check = self._action(m, "&Check the fine scans before leaving", cmd.check_selected,
                                      tip="Measure the fine scans now: every target good, or what to scan again")
        self.act_process = self._action(m, "P&rocess", cmd.process, "F5",
                                        tip="Compute what is new or changed: centroids, then displacements")
        self._action(m, "&Inspect the selected target's fine scan", cmd.show_fine)
        m = mb.addMenu("&Camera")
        self._action(m, "&Import series…", cmd.import_camera)
        self._action(m, "&Cross-validate with LiDAR", cmd.crossval)
        m = mb.addMenu("A&nalysis")
        self._action(m, "Import &environment series (temperature…)…", cmd.import_env)
        self._action(m, "Add &event (construction, load, repair)…", cmd.add_event)
        self._action(m, "Import design &prediction…", cmd.import_prediction)
        self._action(m, "&Analyse", cmd.run_analysis)
        m = mb.addMenu("&Reports")
        self._action(m, "Export &displacements (CSV)…", cmd.export_csv)
        self._action(m, "Export &workbook (XLSX)…", cmd.export_xlsx)
        self.act_report = self._action(m, "Write &report (PDF)…", cmd.write_report, "Ctrl+R")
        self._action(m, "Write report with the &appendix (PDF)…", lambda: cmd.write_report(detail=True))
        m = mb.addMenu("&View")
        m.addAction(self.tree_dock.toggleViewAction())
        m.addAction(self.details_dock.toggleViewAction())
        self._action(m, "Re&load campaign", self.state.refresh, "Ctrl+L")
        m = mb.addMenu("&Help")
        self._action(m, "&About", lambda: QMessageBox.about(
            self, "BridgeSurvey", "BridgeSurvey: long-term bridge displacement from temporarily installed "
                                  "terrestrial LiDAR and a dual-camera system."), None, False)
        tb = self.addToolBar("Main")
        tb.setObjectName("main-toolbar")
        for a in (self.act_open, self.act_add_epoch, self.act_plan, self.act_process, self.act_report):
            tb.addAction(a)
        tb.addSeparator()
        self.act_next = QAction("Next step", self)
        self.act_next.triggered.connect(lambda _c=False: cmd.run_next())
        self.act_next.setVisible(False)
        tb.addAction(self.act_next)
        self.next_btn = tb.widgetForAction(self.act_next)
        if isinstance(self.next_btn, QToolButton):
            self.next_btn.setStyleSheet("QToolButton { font-weight: bold; color: #0b5394; }")

    def _wire(self) -> None:
        st, cmd = self.state, self.commands
        # the campaign
        st.opened.connect(self._opened)
        for view, text in ((self.fine_view, "Select an epoch with fine scans and a target, then Epoch ▸ Inspect the "
                                            "selected target's fine scan."),
                           (self.cloud_view, "Select an epoch and press Show."),
                           (self.stations_view, "Predicts, for scanner positions on a grid around the bridge, the "
                                                "sigma of every target's displacement and the scan time."),
                           (self.analysis_view, "Temperature effect, construction events with creep, trend and "
                                                "projection of every target: press Analyse.")):
            st.opened.connect(lambda _name, view=view, text=text: view.show_message(text))
        st.closed.connect(self._closed)
        st.error.connect(lambda title, message: show_error(self, title, message))
        st.refreshed.connect(self.tree.show_snapshot)
        st.refreshed.connect(self.displacements.show_snapshot)
        st.refreshed.connect(lambda snap: self.zone_label.setText(f"zone {snap.status.get('timezone') or 'UTC'}"))
        st.selection_changed.connect(self.tree.show_selection)
        st.selection_changed.connect(self.displacements.show_selection)
        st.selection_changed.connect(self.map_view.show_selection)
        st.selection_changed.connect(self.cloud_view.show_selection)
        st.details_changed.connect(lambda html: self.details.setHtml(html))
        st.next_step_changed.connect(self._show_next_step)
        st.view_requested.connect(lambda name: self.tabs.setCurrentWidget(self.views[name]))
        self.tabs.currentChanged.connect(lambda i: st.show_view(self.TABS[i][0]))
        # results of jobs
        out = st.outputs
        out.inspection.connect(self.fine_view.set_inspection)
        out.cloud.connect(self.cloud_view.set_cloud)
        out.stations.connect(self.stations_view.show_advice)
        out.analysis.connect(self.analysis_view.show_analysis)
        out.crossval.connect(self.camera_view.set_result)
        out.message.connect(lambda view, text: self.views[view].show_message(text))
        # the status line and jobs
        st.status.changed.connect(lambda m: self.statusBar().showMessage(m.text, m.timeout_ms))
        st.status.progress_changed.connect(self._show_progress)
        self.jobs.started.connect(st.status.started)
        self.jobs.progress.connect(st.status.progress)
        self.jobs.error.connect(st.job_failed)
        self.jobs.finished.connect(lambda _title, ok: st.status.finished(ok=ok))
        self.cancel_btn.clicked.connect(self.cancel_job)
        # gestures
        self.tree.picked.connect(self._tree_picked)
        self.tree.activated_item.connect(self._tree_activated)
        self.displacements.epochPicked.connect(lambda label: st.select(epoch=label))
        self.map_view.reflectorPicked.connect(lambda rid: st.select(reflector=rid))
        self.cloud_view.targetPicked.connect(lambda rid: st.select(reflector=rid))
        self.map_view.saveRequested.connect(cmd.save_plan)
        self.map_view.exportRequested.connect(cmd.export_plan)
        self.map_view.addRequested.connect(cmd.add_window)
        self.cloud_view.loadRequested.connect(cmd.show_cloud)
        self.camera_view.crossvalRequested.connect(cmd.crossval)
        self.camera_view.importRequested.connect(cmd.import_camera)
        self.stations_view.evaluateRequested.connect(cmd.evaluate_stations)
        self.analysis_view.runRequested.connect(cmd.run_analysis)
        self.analysis_view.importRequested.connect(cmd.import_env)

    # ------------------------------------------------------------------ what the state says
    def _opened(self, name: str) -> None:
        self._remember(self.state.folder)
        self.setWindowTitle(f"BridgeSurvey — {name}")
        self.tree_dock.setWindowTitle(f"Campaign: {name}")
        self.stack.setCurrentWidget(self.tabs)
        self._set_campaign_enabled(True)
        self.state.show_view(self.TABS[self.tabs.currentIndex()][0])

    def _closed(self) -> None:
        self.tree.clear()
        self.tree_dock.setWindowTitle("Campaign")
        self.details.clear()
        self.zone_label.clear()
        self.setWindowTitle("BridgeSurvey")
        self.stack.setCurrentWidget(self.welcome)
        self._set_campaign_enabled(False)
        self.act_next.setVisible(False)

    def _show_next_step(self, step) -> None:
        self.act_next.setVisible(step is not None)
        if step is not None:
            self.act_next.setText(step.text)
            self.act_next.setToolTip(step.tooltip)
            self.act_next.setStatusTip(step.tooltip)

    def _show_progress(self, running: bool, fraction: float, cancelling: bool) -> None:
        self.progress.setVisible(running)
        self.cancel_btn.setVisible(running)
        self.progress.setValue(int(fraction * 1000) if running else 0)
        self.cancel_btn.setEnabled(running and not cancelling)
        self.cancel_btn.setText("Cancelling…" if cancelling else "Cancel")

    def _tree_picked(self, kind: str, key: str) -> None:
        if kind == "reflector":
            self.state.select(reflector=key, focus=(kind, key))
        elif kind == "epoch":
            self.state.select(epoch=key, focus=(kind, key))
        else:
            self.state.select(focus=(kind, key))

    def _tree_activated(self, kind: str, key: str) -> None:
        view = {"epoch": "map", "reflector": "displacements", "series": "camera"}.get(kind)
        if view:
            self.state.request_view(view)

    def _set_campaign_enabled(self, on: bool) -> None:
        for a in self._campaign_actions:
            a.setEnabled(on)

    # ------------------------------------------------------------------ campaigns
    def recent(self) -> list[str]:
        v = settings().value("recent", [])
        return [p for p in ([v] if isinstance(v, str) else (v or [])) if p]

    def _remember(self, folder) -> None:
        if folder is None:
            return
        paths = [str(folder)] + [p for p in self.recent() if p != str(folder)]
        settings().setValue("recent", paths[:MAX_RECENT])
        self.welcome.set_recent(paths[:MAX_RECENT])

    def _fill_recent_menu(self) -> None:
        self.recent_menu.clear()
        for p in self.recent():
            a = self.recent_menu.addAction(p)
            a.triggered.connect(lambda _c=False, p=p: self.open_campaign(p))

    def open_campaign(self, folder) -> bool:
        return self.state.open(folder)

    def close_campaign(self) -> None:
        self.state.close()

    def open_dialog(self) -> None:
        folder = ask_folder(self, "Open campaign folder", self.folders, "campaigns")
        if folder:
            self.open_campaign(folder)

    def open_demo(self) -> None:
        if (self.demo_dir / DB_NAME).exists():
            self.open_campaign(self.demo_dir)
            return
        if QMessageBox.question(self, "Demo campaign", f"The demo campaign is not built yet. Build it in "
                                f"{self.demo_dir}? (52 simulated weekly visits, a few minutes)") != QMessageBox.Yes:
            return
        self.commands.build_demo(self.demo_dir)

    # ------------------------------------------------------------------ jobs
    def run_job(self, title: str, fn: Callable, on_done: Callable | None = None) -> bool:
        if not self.jobs.run(title, fn, on_done):
            show_error(self, title, "Another task is still running; wait for it or cancel it first.")
            return False
        return True

    def cancel_job(self) -> None:
        if self.jobs.busy:
            self.state.status.cancelling()
            self.jobs.cancel()

    def dialog_parent(self) -> QWidget:
        return self

    # ------------------------------------------------------------------ shutdown
    def closeEvent(self, event) -> None:  # noqa: N802
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

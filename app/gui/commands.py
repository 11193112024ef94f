"""The main window's commands: plan editing, epoch work, campaign settings, camera and exports.

A mixin of :class:`app.gui.main_window.MainWindow`; each command asks what it needs (dialogs),
then runs the work as a background job through ``self.win.run_job`` and refreshes the views.
"""
from __future__ import annotations

from typing import Any, Callable, Optional, Protocol

from PySide6.QtWidgets import QFileDialog, QInputDialog

from app.gui import actions
from app.gui.state.map_geometry import window_from_cells
from app.gui.views.map_view import cells
from app.gui.dialogs import AddEpochDialog, CheckDialog, ImportCameraDialog, ask_save_path, show_error
from common.errors import SurveyError


class CommandHost(Protocol):
    """What the commands use of the window they serve."""

    session: Any          # app.gui.session.Session: the open campaign, the selected epoch and reflector
    status_data: dict     # projects.overview.campaign_status of the open campaign
    tabs: Any             # QTabWidget holding the views below
    map_view: Any
    fine_view: Any
    cloud_view: Any
    camera_view: Any
    stations_view: Any
    analysis_view: Any

    def run_job(self, title: str, fn: Callable, on_done: Optional[Callable] = None) -> bool: ...

    def statusBar(self) -> Any: ...

    def _changed(self, _result=None) -> None: ...


class Commands:
    """The slots behind the menus, toolbar and view buttons of ``win``."""

    def __init__(self, win: CommandHost):
        self.win = win
        self.check_dialog = None  # the last check's dialog, kept open

    # ------------------------------------------------------------------ map and plan
    def _load_map(self, *, reload: bool = False) -> None:
        """Show the selected epoch's map and plan; the one already shown stays (its windows are live
        items the user may be clicking) unless ``reload`` asks for what the campaign now holds."""
        mv = self.win.map_view
        label = self.win.session.epoch or self._last_epoch()
        if label is None:
            mv.show_message("No epoch yet: add one (Epoch ▸ Add epoch…).")
            return
        if mv.plan is not None and mv.label == label and (mv.dirty or not reload):
            if self.win.session.reflector:
                mv.select_reflector(self.win.session.reflector)
            return  # the same epoch: keep what is shown, unsaved edits above all
        with self.win.session.read() as c:
            preview = c.map_preview(label)
            plan = c.plan(label)
        if preview is None:
            self.win.map_view.show_message(f"Epoch {label} has not been planned yet: Epoch ▸ Plan, or Process.")
            return
        self.win.map_view.load(label, preview, plan)
        if self.win.session.reflector:
            self.win.map_view.select_reflector(self.win.session.reflector)

    def _last_epoch(self) -> Optional[str]:
        eps = self.win.status_data["epochs"]
        return eps[-1]["epoch"] if eps else None

    def save_plan(self, plan) -> None:
        label = self.win.map_view.label
        if plan is None or label is None:
            return

        def done(_r):
            self.win.map_view.editor.mark_saved(plan.rois)
            self.win._changed()

        self.win.run_job(f"Saving the plan of {label}", lambda p: actions.save_plan(self.win.session, label, plan), done)

    def export_plan(self, plan) -> None:
        if plan is None:
            return
        path = ask_save_path(self.win, "Export plan", f"plan-{plan.epoch}.json", "Plan (*.json)")
        if path is not None:
            try:
                plan.save(path)
                self.win.statusBar().showMessage(f"plan written to {path}", 8000)
            except (SurveyError, OSError) as exc:
                show_error(self.win, "Export plan", str(exc))

    def add_window(self, rect) -> None:
        """A window drawn on the map: ask which target it is for and add it with steps for that target."""
        self.win.map_view.draw_btn.setChecked(False)
        if self.win.map_view.plan is None:
            return
        with self.win.session.read() as c:
            refl = {r.id: r for r in c.reflectors() if not r.retired}
        taken = {it.roi.reflector for it in self.win.map_view.items}
        free = [rid for rid in refl if rid not in taken]
        if not free:
            show_error(self.win, "Add window", "Every reflector has a window already; move or resize it instead.")
            return
        rid, ok = QInputDialog.getItem(self.win, "Add window", "Reflector:", free, 0, False)
        if not ok:
            return
        try:
            roi = window_from_cells(self.win.map_view.preview, self.win.map_view.plan, cells(rect), rid, refl[rid])
        except SurveyError as exc:
            show_error(self.win, "Add window", str(exc))
            return
        self.win.map_view.add_roi(roi)

    # ------------------------------------------------------------------ epoch work
    def add_epoch(self) -> None:
        dlg = AddEpochDialog(self.win)
        if dlg.exec() != AddEpochDialog.Accepted:
            return
        v = dlg.values()
        self.win.run_job(f"Importing epoch {v['label']}", lambda p: actions.add_epoch(self.win.session, v, p),
                     lambda label: (self.win._changed(), self.win.session.select(epoch=label)))

    def add_fine(self) -> None:
        label = self.win.session.epoch
        if not label:
            show_error(self.win, "Add fine scans", "Select an epoch in the campaign tree first.")
            return
        from app.gui.dialogs import SCAN_FILTER

        paths, _ = QFileDialog.getOpenFileNames(self.win, f"Fine scans of {label}", "", SCAN_FILTER)
        if paths:
            self.win.run_job(f"Importing fine scans of {label}", lambda p: actions.add_fine(self.win.session, label, paths, p),
                         self.win._changed)

    def plan_selected(self) -> None:
        label = self.win.session.epoch or self._last_epoch()
        if label:
            self.win.run_job(f"Planning {label}", lambda p: actions.plan(self.win.session, label, p), self.win._changed)

    def process(self) -> None:
        self.win.run_job("Processing", lambda p: actions.process(self.win.session, p), self._processed)

    def _processed(self, summary) -> None:
        self.win._changed()
        if summary.failed:
            show_error(self.win, "Processing", "\n".join(f"{o.epoch}: {o.message}" for o in summary.failed))

    def field_sheet(self) -> None:
        label = self.win.session.epoch or self._last_epoch()
        if not label:
            show_error(self.win, "Field sheet", "Add an epoch (its coarse scan) first.")
            return
        path = ask_save_path(self.win, "Field sheet", f"field-sheet-{label}.pdf", "PDF (*.pdf)")
        if path is not None:
            self.win.run_job(f"Writing the field sheet of {label}", lambda p: actions.field_sheet(self.win.session, label, path, p),
                         lambda r: (self.win._changed(), self.win.statusBar().showMessage(f"field sheet written to {r}", 10000)))

    def check_selected(self) -> None:
        label = self.win.session.epoch or self._last_epoch()
        if not label:
            show_error(self.win, "Check", "Select an epoch with fine scans first.")
            return

        def done(result):
            self.win._changed()
            self.check_dialog = CheckDialog(self.win, result)
            self.check_dialog.show()

        self.win.run_job(f"Checking the fine scans of {label}", lambda p: actions.check(self.win.session, label, p), done)

    def evaluate_stations(self, grid_m: Optional[float] = None, height_m: Optional[float] = None) -> None:
        view = self.win.stations_view
        grid_m = view.grid.value() if grid_m is None else grid_m
        height_m = view.height.value() if height_m is None else height_m
        view.grid.setValue(grid_m)
        view.height.setValue(height_m)
        self.win.tabs.setCurrentWidget(view)
        self.win.run_job("Evaluating scanner stations", lambda p: actions.stations(self.win.session, grid_m, height_m, p),
                     lambda r: self.win.stations_view.show_advice(*r))

    def run_analysis(self) -> None:
        self.win.tabs.setCurrentWidget(self.win.analysis_view)
        self.win.run_job("Analysing the displacements", lambda p: actions.analyse(self.win.session),
                     self.win.analysis_view.show_analysis)

    def choose_scanner(self) -> None:
        with self.win.session.read() as c:
            current = c.profile.name
        names = actions.scanner_names()
        name, ok = QInputDialog.getItem(self.win, "Scanner", "The campaign's scanner (planning and noise model):", names,
                                        names.index(current) if current in names else 0, False)
        if ok:
            self._quick("Scanner", lambda: actions.set_scanner(self.win.session, name))

    def show_fine(self) -> None:
        s = self.win.session
        label, rid = s.epoch or self._last_epoch(), s.reflector
        if not label or not rid:
            self.win.fine_view.show_message("Select an epoch and a target (tree, map or 3-D view) first.")
            self.win.tabs.setCurrentWidget(self.win.fine_view)
            return
        self.win.tabs.setCurrentWidget(self.win.fine_view)
        self.win.run_job(f"Reading the window of {rid} in {label}", lambda p: actions.inspect(s, label, rid, p),
                     self.win.fine_view.set_inspection)

    def show_cloud(self, mode: str) -> None:
        s = self.win.session
        label = s.epoch or self._last_epoch()
        if not label:
            return
        self.win.cloud_view.mode.setCurrentIndex(0 if mode == "intensity" else 1)
        if mode == "intensity":
            self.win.run_job(f"Loading the scan of {label}", lambda p: actions.epoch_cloud(s, label, p),
                         self.win.cloud_view.set_cloud)
        else:
            self.win.run_job(f"Comparing {label} with the baseline", lambda p: actions.change_cloud(s, label, p),
                         lambda r: (self.win.cloud_view.set_cloud(r), self.win._changed()))

    # ------------------------------------------------------------------ campaign settings
    def _ask(self, title: str, label: str, text: str = "") -> Optional[str]:
        value, ok = QInputDialog.getText(self.win, title, label, text=text)
        return value.strip() if ok and value.strip() else None

    def _quick(self, title: str, fn: Callable) -> None:
        """Small changes run in the GUI thread; errors are shown, the campaign is left as it was."""
        try:
            fn()
        except SurveyError as exc:
            show_error(self.win, title, str(exc))
            return
        self.win._changed()

    def set_limit(self) -> None:
        rid = self.win.session.reflector or "*"
        rule = self._ask("Set limit", f"Limit rule for {'every measurement target' if rid == '*' else rid} "
                                      "(kr-rail:0-200, abs:10,15 mm or span:1000,500):", "kr-rail:0-200")
        if rule:
            self._quick("Set limit", lambda: actions.set_limit(self.win.session, rid, rule))

    def retire_reflector(self) -> None:
        rid = self.win.session.reflector
        if not rid:
            show_error(self.win, "Retire reflector", "Select a reflector in the campaign tree first.")
            return
        when = self._ask("Retire reflector", f"Retire {rid} from (ISO date):")
        if when:
            self._quick("Retire reflector", lambda: actions.retire_reflector(self.win.session, rid, when))

    def replace_reflector(self) -> None:
        rid = self.win.session.reflector
        if not rid:
            show_error(self.win, "Replace reflector", "Select a reflector in the campaign tree first.")
            return
        new = self._ask("Replace reflector", f"New id of the target replacing {rid}:", f"{rid}b")
        when = new and self._ask("Replace reflector", f"{new} replaces {rid} from (ISO date):")
        if new and when:
            self._quick("Replace reflector", lambda: actions.replace_reflector(self.win.session, rid, new, when))

    def set_parameter(self) -> None:
        from projects.processing.parameters import BY_NAME, PARAMETERS
        from projects.processing.stages import parameters

        with self.win.session.read() as c:
            current = {**parameters(c), **{k: v for k, v in c.settings().items() if k in BY_NAME}}
        keys = [p.name for p in PARAMETERS]
        key, ok = QInputDialog.getItem(self.win, "Processing parameter", "Parameter:", keys, 0, False)
        if not ok:
            return
        p = BY_NAME[key]
        text = self._ask("Processing parameter", f"{key}: {p.help}.\nValues: {p.values}. "
                                                 f"Now {current.get(key)}, default {p.default}.\nNew value:")
        if text is not None:
            self._quick("Processing parameter", lambda: actions.set_parameter(self.win.session, key, text))

    # ------------------------------------------------------------------ camera
    def _load_camera(self) -> None:
        from projects.series.camera import crossval_summaries, load_series
        from vision.crossval import CrossValidation

        with self.win.session.read() as c:
            sums = crossval_summaries(c)
            cam = load_series(c, sums[0]["series"])[1] if sums else None
        if sums:
            self.win.camera_view.set_result(CrossValidation.from_json(sums[0]), cam)
        else:
            self.win.camera_view.show_message("No cross-validation yet: import a camera series, then Camera ▸ "
                                          "Cross-validate with LiDAR.")

    def import_camera(self) -> None:
        from projects.series.camera import midspan_reflector

        with self.win.session.read() as c:
            meas = [r.id for r in c.reflectors() if not r.is_reference and not r.retired]
            try:
                default = midspan_reflector(c)
            except SurveyError:
                default = None
        dlg = ImportCameraDialog(meas, default, self.win)
        if dlg.exec() != ImportCameraDialog.Accepted:
            return
        v = dlg.values()
        self.win.run_job("Importing the camera series", lambda p: actions.import_camera(self.win.session, v, p),
                     self.win._changed)

    def crossval(self) -> None:
        def done(_r):
            self.win._changed()
            self.win.tabs.setCurrentWidget(self.win.camera_view)
            self._load_camera()

        self.win.run_job("Cross-validating", lambda p: actions.crossval(self.win.session, p), done)

    # ------------------------------------------------------------------ exports
    def export_csv(self) -> None:
        path = ask_save_path(self.win, "Export displacements", "displacements.csv", "CSV (*.csv)")
        if path is not None:
            self.win.run_job("Exporting displacements", lambda p: actions.export_csv(self.win.session, path))

    def export_xlsx(self) -> None:
        path = ask_save_path(self.win, "Export workbook", "campaign.xlsx", "Excel workbook (*.xlsx)")
        if path is not None:
            self.win.run_job("Exporting the workbook", lambda p: actions.export_xlsx(self.win.session, path))

    def write_report(self) -> None:
        path = ask_save_path(self.win, "Write report", "report.pdf", "PDF (*.pdf)")
        if path is not None:
            self.win.run_job("Writing the report", lambda p: actions.report(self.win.session, path, p),
                         lambda r: self.win.statusBar().showMessage(f"report written to {r}", 10000))

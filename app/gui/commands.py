"""The window's commands: what the menus, the toolbar and the views' buttons do.

Each command asks what it needs (dialogs), runs the work (:mod:`app.gui.actions`, plain functions)
as a background job through its host, and tells the application's state what came of it
(:class:`app.gui.state.app_state.AppState`: a refresh, a selection, a view to show, a result for a
view, a status line). No command touches a view.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QInputDialog, QMessageBox

from app.gui import actions
from app.gui.dialogs import (
    AddEpochDialog,
    AddEventDialog,
    CheckDialog,
    ImportCameraDialog,
    ImportEnvDialog,
    ImportPredictionDialog,
    NewCampaignDialog,
    SetLimitDialog,
    ask_files,
    ask_folder,
    ask_save_path,
)
from app.gui.state.app_state import AppState
from app.gui.state.cloud_display import prepare_cloud
from app.gui.state.folders import LastFolders
from app.gui.state.words import archive_question, in_app_words, nothing_to_archive, restore_question, windows_text
from app.gui.views.fine_figure import draw_inspection
from app.gui.views.fleet_view import FleetView
from common.errors import SurveyError
from common.progress import scaled
from projects.processing.parameters import BY_NAME, PARAMETERS
from projects.processing.stages import parameters
from projects.series.camera import midspan_reflector


class CommandHost(Protocol):
    """What the commands use of the window they serve."""

    state: AppState
    folders: LastFolders

    def run_job(self, title: str, fn: Callable, on_done: Callable | None = None) -> bool: ...

    def dialog_parent(self) -> Any: ...


class Commands:
    """The slots behind the menus, toolbar and view buttons of ``host``."""

    def __init__(self, host: CommandHost):
        self.host = host
        self.check_dialog: CheckDialog | None = None  # the last check's dialog, kept open
        self.fleet_view = None

    @property
    def state(self) -> AppState:
        return self.host.state

    @property
    def parent(self):
        return self.host.dialog_parent()

    def _job(self, title: str, fn: Callable, on_done: Callable | None = None) -> bool:
        return self.host.run_job(title, fn, on_done)

    def _refresh(self, _result=None) -> None:
        self.state.refresh()

    def _need_epoch(self, title: str, what: str = "an epoch") -> str | None:
        label = self.state.epoch_or_latest
        if label is None:
            self.state.report_error(title, f"The campaign has no epoch yet: add {what} first (Epoch ▸ Add epoch…).")
        return label

    def _quick(self, title: str, fn: Callable, done: Callable[[Any], str] | None = None) -> bool:
        """Small changes run in the GUI thread; errors are shown, the campaign is left as it was.

        ``done(result)`` gives the status line saying what was changed."""
        try:
            result = fn()
        except SurveyError as exc:
            self.state.report_error(title, str(exc))
            return False
        self.state.refresh()
        self.state.status.result(done(result) if done is not None else f"{title}: done")
        return True

    def run_next(self) -> None:
        """Do the next step the state shows (:mod:`app.gui.state.next_step`)."""
        step = self.state.next
        if step is None:
            return
        if step.epoch is not None:
            self.state.select(epoch=step.epoch)
        {"add_epoch": self.add_epoch, "plan": self.plan_selected, "add_fine": self.add_fine, "add_setup": self.add_setup,
         "check": self.check_selected, "process": self.process, "report": self.write_report}[step.command]()

    # ------------------------------------------------------------------ campaigns
    def new_campaign(self) -> None:
        dlg = NewCampaignDialog(self.parent, self.host.folders)
        if dlg.exec() != NewCampaignDialog.Accepted:
            return
        v = dlg.values()
        self._job(f"Creating the campaign {v['name'] or v['folder']}", lambda p: actions.create_campaign(**v),
                  self.state.open)

    def build_demo(self, folder: Path) -> None:
        self._job("Building the demo campaign", lambda p: actions.build_demo(folder, p),
                  lambda _r: self.state.open(folder))

    def open_fleet(self, folder: str | None = None) -> None:
        """List every campaign under a folder (worst state first) and open any of them."""
        folder = folder or ask_folder(self.parent, "Folder holding the campaigns", self.host.folders, "campaigns")
        if not folder:
            return

        def done(status):
            self.fleet_view = view = FleetView(self.parent)
            view.openRequested.connect(lambda f: (self.state.open(f), view.close()))
            view.show_status(status)
            view.show()

        self._job(f"Reading the campaigns under {folder}", lambda p: actions.fleet_status(folder), done)

    # ------------------------------------------------------------------ map and plan
    def save_plan(self, plan) -> None:
        label = self.state.map.label
        if plan is None or label is None:
            return
        cut = self.state.map.cut_targets(plan)
        if cut:  # said before it is saved: a window that cuts its target gives fewer points than the plan says
            names = ", ".join(f"{r.reflector} (planned {r.expected_target_points:,} points on it)" for r in cut)
            if QMessageBox.question(self.parent, "Save plan", f"These windows do not hold their whole target: "
                                    f"{names}. The scan would give fewer points on them than planned. Save anyway?",
                                    QMessageBox.Yes | QMessageBox.No, QMessageBox.No) != QMessageBox.Yes:
                self.state.status.result("plan not saved: widen or move the windows over their targets")
                return

        def done(_r):
            self.state.map.editor.mark_saved(plan.rois)
            self.state.status.result(f"plan of {label} saved; Epoch ▸ Process measures {label} again with it")
            self.state.refresh()

        self._job(f"Saving the plan of {label}", lambda p: actions.save_plan(self.state.access, label, plan), done)

    def export_plan(self, plan) -> None:
        if plan is None:
            return
        path = ask_save_path(self.parent, "Export plan", self.host.folders, f"plan-{plan.epoch}.json",
                             "Plan (*.json)")
        if path is not None:
            try:
                plan.save(path)
            except (SurveyError, OSError) as exc:
                self.state.report_error("Export plan", str(exc))
                return
            self.state.status.result(f"plan written to {path}")

    def add_window(self, rect) -> None:
        """A window drawn on the map (a :class:`app.gui.state.map_geometry.CellRect`): ask which target it
        is for and add it with steps for that target."""
        if self.state.map.editor.plan is None:
            return
        refl = {r.id: r for r in self.state.snapshot.reflectors}
        free = self.state.map.free_targets(refl.values())
        if not free:
            self.state.report_error("Add window", "Every reflector has a window already; move or resize it instead.")
            return
        rid, ok = QInputDialog.getItem(self.parent, "Add window", "Target of the new window:", free, 0, False)
        if not ok:
            return
        try:
            roi = self.state.map.window_for(rect, refl[rid])
        except SurveyError as exc:
            self.state.report_error("Add window", str(exc))
            return
        self.state.map.editor.add(roi)

    # ------------------------------------------------------------------ epoch work
    def add_epoch(self) -> None:
        dlg = AddEpochDialog(self.parent, self.host.folders)
        if dlg.exec() != AddEpochDialog.Accepted:
            return
        v = dlg.values()

        def done(label):
            self.state.refresh()
            self.state.select(epoch=label)
            self.state.status.result(f"epoch {label} added; next: plan it (Epoch ▸ Plan the selected epoch)")

        self._job(f"Importing epoch {v['label']}", lambda p: actions.add_epoch(self.state.access, v, p), done)

    def add_fine(self) -> None:
        label = self._need_epoch("Add fine scans")
        if not label:
            return
        paths = ask_files(self.parent, f"Fine scans of {label}", self.host.folders, "scans")
        if not paths:
            return

        def done(_r):
            self.state.refresh()
            self.state.status.result(f"{len(paths)} fine scan(s) added to {label}; next: check them before "
                                     "leaving (Epoch ▸ Check the fine scans before leaving)")

        self._job(f"Importing fine scans of {label}", lambda p: actions.add_fine(self.state.access, label, paths, p),
                  done)

    def add_setup(self) -> None:
        label = self._need_epoch("Add set-up")
        if not label:
            return
        paths = ask_files(self.parent, f"Coarse scan of another set-up (station) of {label}", self.host.folders,
                          "scans")
        if not paths:
            return
        if len(paths) != 1:
            self.state.status.result("choose one coarse scan: each set-up has its own")
            return

        def done(result):
            new, plans = result
            self.state.refresh()
            what = ", ".join(f"set-up {k}: {windows_text(p.rois)}, {p.total_seconds / 60:.1f} min"
                             for k, p in zip(new, plans, strict=False))
            self.state.status.result(f"{label}: {what}; next: scan them and add the fine scans (Epoch ▸ Add fine "
                                     "scans to the selected epoch…, they go to the set-up added last)")

        self._job(f"Adding a set-up to {label}", lambda p: actions.add_setup(self.state.access, label, paths[0], p),
                  done)

    def plan_selected(self) -> None:
        label = self._need_epoch("Plan")
        if not label:
            return

        def done(plan):
            self.state.refresh()
            self.state.select(epoch=label)
            self.state.request_view("map")
            self.state.status.result(f"{label} planned: {windows_text(plan.rois)}, {plan.total_seconds / 60:.1f} min; "
                                     "export the plan for the scanner (Export plan JSON…) or print the field sheet")

        self._job(f"Planning {label}", lambda p: actions.plan(self.state.access, label, p), done)

    def process(self) -> None:
        pending = actions.pending_rescans(self.state.access)  # the check is binding: its re-scan asks first
        if pending:
            lines = "\n".join(f"{label}: {line}" for label, line in pending.items())
            answer = QMessageBox.question(
                self.parent, "Process", f"The check before leaving asked for a re-scan:\n\n{lines}\n\nProcess as it "
                "is anyway? (No: add the re-scan's fine scans first, Epoch ▸ Add fine scans to the selected "
                "epoch…)",
                QMessageBox.Yes | QMessageBox.No, QMessageBox.No)
            if answer != QMessageBox.Yes:
                self.state.status.result("not processed: the re-scan first (Epoch ▸ Add fine scans to the selected "
                                         "epoch…)")
                return
        accept = tuple(pending)

        def done(summary):
            self.state.refresh()
            if summary.failed:
                self.state.report_error("Processing", "; ".join(f"{o.epoch}: {o.message}" for o in summary.failed))

        self._job("Processing", lambda p: actions.process(self.state.access, p, accept_check=accept), done)

    def field_sheet(self) -> None:
        label = self._need_epoch("Field sheet", "an epoch (its coarse scan)")
        if not label:
            return
        path = ask_save_path(self.parent, "Field sheet", self.host.folders, f"field-sheet-{label}.pdf", "PDF (*.pdf)")
        if path is not None:
            def done(r):
                self.state.refresh()
                self.state.status.result(f"field sheet written to {r}")

            self._job(f"Writing the field sheet of {label}",
                      lambda p: actions.field_sheet(self.state.access, label, path, p), done)

    def check_selected(self) -> None:
        label = self._need_epoch("Check", "an epoch with fine scans")
        if not label:
            return

        def done(result):
            self.state.refresh()
            self.check_dialog = CheckDialog(self.parent, result, self.host.folders)
            self.check_dialog.show()
            self.state.status.result(f"{label} checked: " + (
                "every target is good; next: Epoch ▸ Process" if not result.short else
                f"re-scan {', '.join(t.reflector for t in result.short)} before leaving"))

        self._job(f"Checking the fine scans of {label}", lambda p: actions.check(self.state.access, label, p), done)

    def evaluate_stations(self, grid_m: float, height_m: float) -> None:
        self.state.request_view("stations")
        self._job("Evaluating scanner stations", lambda p: actions.stations(self.state.access, grid_m, height_m, p),
                  lambda r: self.state.outputs.stations.emit(*r))

    def run_analysis(self) -> None:
        self.state.request_view("analysis")
        def done(doc):
            self.state.outputs.analysis.emit({**doc, "warnings": [in_app_words(w) for w in doc["warnings"]]})

        self._job("Analysing the displacements", lambda p: actions.analyse(self.state.access), done)

    def choose_scanner(self) -> None:
        with self.state.read() as c:
            current = c.profile.name
        names = actions.scanner_names()
        name, ok = QInputDialog.getItem(self.parent, "Scanner", "The campaign's scanner (planning and noise model):",
                                        names, names.index(current) if current in names else 0, False)
        if ok:
            self._quick("Scanner", lambda: actions.set_scanner(self.state.access, name),
                        lambda _r: f"the campaign's scanner is now the {name}; plans from now on use it")

    def show_fine(self) -> None:
        sel = self.state.selection
        label, rid = self.state.epoch_or_latest, sel.reflector
        self.state.request_view("fine")
        if not label or not rid:
            self.state.outputs.message.emit("fine", "Select an epoch and a target (tree, map or 3-D view), then "
                                                    "Epoch ▸ Inspect the selected target's fine scan.")
            return
        def job(p):  # read and drawn in the worker: the view only shows the picture
            ins = actions.inspect(self.state.access, label, rid, scaled(p, 0.0, 0.7))
            p(0.7, "drawing the window")
            return draw_inspection(ins)

        self._job(f"Reading the window of {rid} in {label}", job, self.state.outputs.inspection.emit)

    def show_cloud(self, mode: str) -> None:
        label = self._need_epoch("3-D view")
        if not label:
            return

        def done(prepared):  # only the hand-over to VTK runs here: the cloud was thinned and prepared in the job
            self.state.outputs.cloud.emit(prepared)
            if mode != "intensity":
                self.state.refresh()
            self.state.status.result(prepared.status)

        if mode == "intensity":
            self._job(f"Loading the scan of {label}",
                      lambda p: prepare_cloud(actions.epoch_cloud(self.state.access, label, scaled(p, 0.0, 0.9)),
                                              progress=scaled(p, 0.9, 1.0)), done)
        else:
            self._job(f"Comparing {label} with the baseline",
                      lambda p: prepare_cloud(actions.change_cloud(self.state.access, label, scaled(p, 0.0, 0.95)),
                                              progress=scaled(p, 0.95, 1.0)), done)

    # ------------------------------------------------------------------ campaign settings
    def _ask(self, title: str, label: str, text: str = "") -> str | None:
        value, ok = QInputDialog.getText(self.parent, title, label, text=text)
        return value.strip() if ok and value.strip() else None

    def set_limit(self) -> None:
        meas = [r.id for r in self.state.snapshot.reflectors if not r.is_reference and not r.retired]
        sel = self.state.selection.reflector
        dlg = SetLimitDialog(self.parent, meas, sel if sel in meas else None)
        if dlg.exec() != SetLimitDialog.Accepted:
            return
        v = dlg.values()
        self._quick("Set limit", lambda: actions.set_limit(self.state.access, v["reflector"], v["rule"]), str)

    def retire_reflector(self) -> None:
        rid = self.state.selection.reflector
        if not rid:
            self.state.report_error("Retire reflector", "Select a reflector in the campaign tree first.")
            return
        when = self._ask("Retire reflector", f"Retire {rid} from (date, YYYY-MM-DD):")
        if when:
            self._quick("Retire reflector", lambda: actions.retire_reflector(self.state.access, rid, when),
                        lambda _r: f"{rid} retired from {when}")

    def replace_reflector(self) -> None:
        rid = self.state.selection.reflector
        if not rid:
            self.state.report_error("Replace reflector", "Select a reflector in the campaign tree first.")
            return
        new = self._ask("Replace reflector", f"Id of the new target replacing {rid}:", f"{rid}b")
        when = new and self._ask("Replace reflector", f"{new} replaces {rid} from (date, YYYY-MM-DD):")
        if new and when:
            self._quick("Replace reflector", lambda: actions.replace_reflector(self.state.access, rid, new, when),
                        lambda _r: f"{new} replaces {rid} from {when}; its history continues {rid}'s")

    def set_parameter(self) -> None:
        with self.state.read() as c:
            current = {**parameters(c), **{k: v for k, v in c.settings().items() if k in BY_NAME}}
        keys = [p.name for p in PARAMETERS]
        key, ok = QInputDialog.getItem(self.parent, "Processing parameter", "Parameter:", keys, 0, False)
        if not ok:
            return
        p = BY_NAME[key]
        text = self._ask("Processing parameter", f"{key}: {p.help}.\nValues: {p.values}. "
                                                 f"Now {current.get(key)}, default {p.default}.\nNew value:")
        if text is not None:
            self._quick("Processing parameter", lambda: actions.set_parameter(self.state.access, key, text),
                        lambda _r: f"{key} = {text}; Epoch ▸ Process computes what it changes")

    # ------------------------------------------------------------------ camera
    def import_camera(self) -> None:
        with self.state.read() as c:
            meas = [r.id for r in c.reflectors() if not r.is_reference and not r.retired]
            try:
                default = midspan_reflector(c)
            except SurveyError:
                default = None
            zone = c.timezone
        dlg = ImportCameraDialog(meas, default, self.parent, self.host.folders, zone=zone)
        if dlg.exec() != ImportCameraDialog.Accepted:
            return
        v = dlg.values()

        def done(r):
            name, summary = r
            self.state.refresh()
            self.state.status.result(f"camera series {name!r} imported: {summary['rows']:,} rows, "
                                     f"{summary['bad_rows']} bad row(s) left out, times {summary['times']}; "
                                     "next: Camera ▸ Cross-validate with LiDAR")

        self._job("Importing the camera series", lambda p: actions.import_camera(self.state.access, v, p), done)

    def crossval(self) -> None:
        def done(_r):
            self.state.refresh()
            self.state.request_view("camera")

        self._job("Cross-validating", lambda p: actions.crossval(self.state.access, p), done)

    # ------------------------------------------------------------------ analysis inputs
    def import_env(self) -> None:
        with self.state.read() as c:
            zone = c.timezone
        dlg = ImportEnvDialog(self.parent, self.host.folders, zone=zone)
        if dlg.exec() != ImportEnvDialog.Accepted:
            return
        v = dlg.values()

        def done(r):
            name, summary = r
            self.state.refresh()
            self.state.status.result(f"{v['kind']} series {name!r} imported: {summary['rows']:,} rows, "
                                     f"{summary['bad_rows']} bad row(s) left out, times {summary['times']}; "
                                     "next: Analysis ▸ Analyse")

        self._job("Importing the environment series", lambda p: actions.import_env(self.state.access, v, p), done)

    def add_event(self) -> None:
        dates = [e["datetime"][:10] for e in self.state.snapshot.status["epochs"]]
        dlg = AddEventDialog(self.parent, dates[-1] if dates else None)
        if dlg.exec() != AddEventDialog.Accepted:
            return
        v = dlg.values()
        self._quick("Add event", lambda: actions.add_event(self.state.access, v),
                    lambda _id: f"event '{v['label']}' on {v['date']} added; Analysis ▸ Analyse fits its step")

    def import_prediction(self) -> None:
        with self.state.read() as c:
            casting = c.settings().get("casting_date")
        dlg = ImportPredictionDialog(self.parent, self.host.folders, casting)
        if dlg.exec() != ImportPredictionDialog.Accepted:
            return
        v = dlg.values()

        def done(out):
            self.state.refresh()
            self.state.status.result(f"design prediction imported for {len(out)} target(s)")

        self._job("Importing the design prediction", lambda p: actions.import_prediction(self.state.access, v, p),
                  done)

    # ------------------------------------------------------------------ exports
    def export_csv(self) -> None:
        path = ask_save_path(self.parent, "Export displacements", self.host.folders, "displacements.csv",
                             "CSV (*.csv)")
        if path is not None:
            self._job("Exporting displacements", lambda p: actions.export_csv(self.state.access, path),
                      lambda r: self.state.status.result(f"displacements written to {r}"))

    def export_xlsx(self) -> None:
        path = ask_save_path(self.parent, "Export workbook", self.host.folders, "campaign.xlsx",
                             "Excel workbook (*.xlsx)")
        if path is not None:
            self._job("Exporting the workbook", lambda p: actions.export_xlsx(self.state.access, path),
                      lambda r: self.state.status.result(f"workbook written to {r}"))

    def verify_campaign(self) -> None:
        """Campaign ▸ Verify campaign: the database, every imported file and every stored result."""
        def done(findings):
            text = "\n".join(in_app_words(f.line()) for f in findings) or \
                "The database, every imported file and every stored result are as they were stored."
            QMessageBox.information(self.parent, "Verify campaign", text)
            problems = [f for f in findings if not f.is_note]  # an archived scan not reachable is only named
            self.state.status.result("verify: " + (f"{len(problems)} thing(s) to do" if problems else "no problem"))

        self._job("Verifying the campaign", lambda p: actions.verify(self.state.access, p), done)

    def repair_campaign(self) -> None:
        """Campaign ▸ Repair campaign: register again what a restored database lost (never deletes)."""
        def fn():
            done, left = actions.repair(self.state.access)
            lines = [f"repaired: {d}" for d in done] + [f"left as it is: {x}" for x in left]
            QMessageBox.information(self.parent, "Repair campaign", in_app_words(
                "\n".join(lines) or "Nothing to repair; nothing was deleted."))
            return len(done)

        self._quick("Repair campaign", fn, lambda n: f"repair: {n} repair(s); nothing was deleted")

    # ------------------------------------------------------------------ scans out of the campaign and back
    def _then(self, title: str, fn: Callable, on_done: Callable | None = None) -> None:
        """Start a job once the one calling this has finished (its end resets the progress bar)."""
        QTimer.singleShot(0, lambda: self._job(title, fn, on_done))

    def archive_scans(self) -> None:
        """Campaign ▸ Archive processed scans…: a folder (another disk), what would move, then the move."""
        dest = ask_folder(self.parent, "Archive processed scans to (a folder on another disk)", self.host.folders,
                          "archives")
        if not dest:
            return

        def ask(move) -> None:
            if not move.run.moved:
                QMessageBox.information(self.parent, "Archive processed scans", nothing_to_archive(move))
                self.state.status.result("archive: nothing to move")
                return
            if QMessageBox.question(self.parent, "Archive processed scans", archive_question(move, dest),
                                    QMessageBox.Yes | QMessageBox.No, QMessageBox.No) != QMessageBox.Yes:
                self.state.status.result("archive: nothing was moved")
                return
            self._then("Archiving scans", lambda p: actions.archive(self.state.access, dest, p), done)

        def done(move) -> None:
            self.state.refresh()
            self.state.status.result(f"archived {len(move.run.moved)} scan(s) of {len(move.run.epochs)} visit(s) to "
                                     f"{dest}: {(move.size - move.after) / 1e6:.1f} MB freed")

        self._job("Looking at what to archive", lambda p: actions.archive(self.state.access, dest, p, dry_run=True),
                  ask)

    def restore_scans(self, source: str | None = None) -> None:
        """Campaign ▸ Restore scans…: what would come back from where, then the copies, each checked. When the
        recorded archive folder is out of reach, a folder picker asks where the archive disk is mounted now."""
        def ask(move) -> None:
            if move.unreachable:
                where = " and ".join(move.unreachable)
                if QMessageBox.question(
                        self.parent, "Restore scans", f"The archived scans are not at {where} (the archive disk is not "
                        "connected, or mounted somewhere else). Choose the folder they are in now?",
                        QMessageBox.Yes | QMessageBox.No, QMessageBox.Yes) != QMessageBox.Yes:
                    self.state.status.result("restore: nothing was brought back")
                    return
                folder = ask_folder(self.parent, "The folder of the archived scans", self.host.folders, "archives")
                if folder:
                    QTimer.singleShot(0, lambda: self.restore_scans(folder))
                return
            if not move.run.moved:
                QMessageBox.information(self.parent, "Restore scans", "Nothing to restore: no scan is archived.")
                self.state.status.result("restore: nothing archived")
                return
            if QMessageBox.question(self.parent, "Restore scans", restore_question(move),
                                    QMessageBox.Yes | QMessageBox.No, QMessageBox.Yes) != QMessageBox.Yes:
                self.state.status.result("restore: nothing was brought back")
                return
            self._then("Restoring scans", lambda p: actions.restore(self.state.access, source, p), done)

        def done(move) -> None:
            self.state.refresh()
            self.state.status.result(f"brought back {len(move.run.moved)} scan(s) of {len(move.run.epochs)} visit(s), "
                                     "each checked against its checksum")

        self._job("Looking at what to restore",
                  lambda p: actions.restore(self.state.access, source, p, dry_run=True), ask)

    def write_report(self, *, detail: bool = False) -> None:
        """The owner's report (main body); ``detail``: with the appendix (every visit's page, the action log)."""
        path = ask_save_path(self.parent, "Write report" + (" with the appendix" if detail else ""),
                             self.host.folders, "report.pdf", "PDF (*.pdf)")
        if path is not None:
            self._job("Writing the report", lambda p: actions.report(self.state.access, path, p, detail=detail),
                      lambda r: self.state.status.result(f"report written to {r}"))

"""The main window driven like a user would: open, select, edit the plan, process, inspect, export."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QPointF

from projects.store.campaign import Campaign
from tests.app.gui.conftest import wait_job
from tests.app.gui.helpers import drag
from tests.projects.campaign_helpers import snapshot

pytestmark = pytest.mark.gui


def test_welcome_page_without_campaign_and_recent_list(window, processed_copy):
    assert window.stack.currentWidget() is window.welcome
    assert not window.act_process.isEnabled()
    assert window.open_campaign(processed_copy)
    assert window.stack.currentWidget() is window.tabs and window.act_process.isEnabled()
    assert window.recent()[0] == str(processed_copy)
    assert window.welcome.recent.item(0).text() == str(processed_copy)


def test_tree_details_and_selection_follow_each_other(window, processed_copy, qtbot):
    window.open_campaign(processed_copy)
    t = window.tree
    assert t.item_for("reflector", "M3") is not None and t.item_for("reflector", "R1") is not None
    assert [t.item_for("epoch", e) is not None for e in ("2026-03-02", "2026-03-09", "2026-03-16")] == [True] * 3
    assert t.item_for("epoch", "2026-03-16").text(1) == "processed"
    t.select_key("reflector", "M3")
    assert window.state.selection.reflector == "M3"
    assert "Reflector M3" in window.details.toPlainText() and "Latest" in window.details.toPlainText()
    assert window.displacements.target.currentText() == "M3"
    t.select_key("epoch", "2026-03-09")
    assert window.state.selection.epoch == "2026-03-09"
    assert "Centroids" in window.details.toPlainText()


def test_displacement_view_hover_values_and_click_selects_the_epoch(window, processed_copy, qtbot):
    from matplotlib.backend_bases import MouseEvent

    window.open_campaign(processed_copy)
    v = window.displacements
    v.show_target("M3")
    v.canvas.draw()
    x, y, hist, i = v._points[1]
    epoch = hist.epochs[i]
    ax = v.canvas.figure.axes[0]
    px, py = ax.transData.transform((ax.convert_xunits(x), y))
    v.canvas.callbacks.process("motion_notify_event", MouseEvent("motion_notify_event", v.canvas, px, py))
    assert v.hover.text().startswith(f"M3 {epoch}: ") and "±" in v.hover.text()
    v.canvas.callbacks.process("button_press_event", MouseEvent("button_press_event", v.canvas, px, py, button=1))
    assert window.state.selection.epoch == epoch


def test_the_legend_goes_to_a_corner_when_many_points_are_drawn(window, processed_copy, monkeypatch):
    import app.gui.views.displacement_view as dv

    window.open_campaign(processed_copy)
    v = window.displacements
    v.redraw()
    assert 0 < len(v._points) <= dv.BEST_LEGEND_POINTS
    assert v.canvas.figure.axes[0].get_legend()._loc == 0  # 'best': the least crowded place
    monkeypatch.setattr(dv, "BEST_LEGEND_POINTS", len(v._points) - 1)  # ten years of visits, say
    v.redraw()
    assert v.canvas.figure.axes[0].get_legend()._loc == 2  # 'upper left', without trying every place


def test_roi_move_resize_delete_add_and_save_then_process(window, processed_copy, qtbot, monkeypatch):
    window.open_campaign(processed_copy)
    window.tree.select_key("epoch", "2026-03-09")
    window.tabs.setCurrentWidget(window.map_view)
    mv = window.map_view
    assert len(mv.items) == 9 and mv.table.rowCount() == 9
    qtbot.wait(20)  # the view fits itself once shown: let it, then zoom for the gestures
    item = next(it for it in mv.items if it.roi.reflector == "M3")
    zoom = 150.0 / item.scene_rect().width()  # the window ~150 px wide on screen
    mv.view.resetTransform()
    mv.view.scale(zoom, zoom)
    mv.view.centerOn(item)
    qtbot.wait(20)
    before = item.roi
    total_before = mv.plan.total_seconds
    r = item.scene_rect()
    drag(mv.view, r.center(), r.center() + QPointF(r.width() / 3, r.height() / 4))  # move
    moved = item.roi
    assert moved.window.phi_min_deg != before.window.phi_min_deg
    assert moved.expected_target_points == before.expected_target_points  # steps unchanged
    r = item.scene_rect()
    edge = QPointF(r.right() - 2 / zoom, r.center().y())
    drag(mv.view, edge, edge + QPointF(r.width() / 2, 0.0))           # widen by the right edge
    wider = item.roi
    assert wider.window.phi_max_deg - wider.window.phi_min_deg > moved.window.phi_max_deg - moved.window.phi_min_deg
    assert wider.expected_points > moved.expected_points and mv.plan.total_seconds > total_before
    assert "edited, not saved" in mv.total.text()
    mv.undo_btn.click()  # the resize is one step: undo puts the moved window back, redo widens it again
    assert item.roi == moved and item.scene_rect().width() < r.width() * 1.2 and mv.redo_btn.isEnabled()
    mv.redo_btn.click()
    assert item.roi == wider and not mv.redo_btn.isEnabled()
    row = [mv.table.item(k, 0).text() for k in range(mv.table.rowCount())].index("M3")
    assert mv.table.item(row, 6).text() == f"{wider.expected_seconds:.1f}"
    # delete M5's window, then draw a new one for it
    m5 = next(it for it in mv.items if it.roi.reflector == "M5")
    m5_rect = m5.scene_rect()
    mv.scene.clearSelection()
    m5.setSelected(True)
    mv.delete_selected()
    assert len(mv.items) == 8
    monkeypatch.setattr("app.gui.commands.QInputDialog.getItem", lambda *a, **k: ("M5", True))
    mv.view.resetTransform()
    mv.view.scale(zoom, zoom)
    mv.view.centerOn(m5_rect.center())
    mv.draw_btn.setChecked(True)
    drag(mv.view, m5_rect.topLeft(), m5_rect.bottomRight())
    assert len(mv.items) == 9 and not mv.draw_btn.isChecked()
    new_m5 = next(it for it in mv.items if it.roi.reflector == "M5").roi
    assert new_m5.expected_target_points >= 500  # steps chosen for the target at the map's range
    window.commands.save_plan(mv.current_plan())
    wait_job(qtbot, window)
    with Campaign.open(processed_copy, writable=False) as c:
        saved = c.stored_plan("2026-03-09").plan_json
        assert saved["edited"] is True
        m3 = next(r for r in saved["rois"] if r["reflector"] == "M3")
        assert m3["phi_max_deg"] == pytest.approx(wider.window.phi_max_deg)
        assert c.result("2026-03-09").stage == "planned"  # measured again at the next processing
    window.commands.process()
    wait_job(qtbot, window)
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.result("2026-03-09").stage == "measured"
        assert c.centroids("2026-03-09")["M3"].found and c.centroids("2026-03-09")["M5"].found
        from projects.results.state import epoch_state

        state, flags = epoch_state(c, "2026-03-09")  # a hand-drawn window may leave a doubt: shown, not hidden
    assert state in ("processed", "warning") and window.tree.item_for("epoch", "2026-03-09").text(1) == state, flags


def test_fine_scan_view_shows_the_split_cluster_and_centroid(window, processed_copy, qtbot):
    window.open_campaign(processed_copy)
    window.state.select(epoch="2026-03-16", reflector="M3")
    window.commands.show_fine()
    wait_job(qtbot, window)
    ins = window.fine_view.inspection
    assert ins is not None and ins.centroid.found
    assert ins.disc.sum() == ins.centroid.n_points and ins.bright.sum() >= ins.cluster.sum() >= ins.disc.sum()
    assert np.linalg.norm(ins.centroid.xyz_socs - ins.stored.xyz_socs) < 1e-9  # the same computation as processing
    assert "σx/σy/σz" in window.fine_view.info.text()
    assert len(window.fine_view.picture.figure.axes) >= 2 and not window.fine_view.image.pixmap().isNull()


def test_new_campaign_add_epoch_plan_and_a_bad_file(window, field_copy, tmp_path, qtbot, errors, monkeypatch):
    from app.gui.dialogs import AddEpochDialog, NewCampaignDialog

    camp = tmp_path / "new"
    monkeypatch.setattr(NewCampaignDialog, "exec", lambda self: NewCampaignDialog.Accepted)
    monkeypatch.setattr(NewCampaignDialog, "values", lambda self: {
        "folder": str(camp), "name": "GUI bridge", "layout": str(field_copy / "layout.csv"), "span_m": 40.0,
        "diameter_mm": 50.0, "timezone": "UTC"})
    window.commands.new_campaign()
    wait_job(qtbot, window)
    assert window.state.is_open and window.state.name == "GUI bridge"
    values = {"datetime": "2026-04-01T09:00:00Z", "label": "2026-04-01", "coarse": str(field_copy / "v0" / "coarse.laz"),
              "fines": [], "notes": "from the GUI"}
    monkeypatch.setattr(AddEpochDialog, "exec", lambda self: AddEpochDialog.Accepted)
    monkeypatch.setattr(AddEpochDialog, "values", lambda self: dict(values))
    window.commands.add_epoch()
    wait_job(qtbot, window)
    assert window.tree.item_for("epoch", "2026-04-01").text(1) == "imported *"  # * : work to do (process)
    window.commands.plan_selected()
    wait_job(qtbot, window)
    assert window.tree.item_for("epoch", "2026-04-01").text(1) == "planned"
    window.tabs.setCurrentWidget(window.map_view)
    assert len(window.map_view.items) == 9
    # a garbage scan: one message in a dialog, the campaign unchanged
    bad = tmp_path / "broken.laz"
    bad.write_bytes(b"LASF" + b"\0" * 50)
    before = snapshot(camp)
    values.update(label="2026-04-08", coarse=str(bad), datetime="2026-04-08T09:00:00Z")
    window.commands.add_epoch()
    wait_job(qtbot, window)
    assert errors and str(bad) in errors[-1][1] and "\n" not in errors[-1][1]
    assert snapshot(camp) == before


def test_camera_import_crossval_and_report_export(window, processed_copy, tmp_path, qtbot, monkeypatch, errors):
    from app.gui.dialogs import ImportCameraDialog
    from tests.projects.series.test_camera import _ns, truth
    from vision.simulate.series import simulate_series, write_series_csv

    t, v = simulate_series(_ns("2026-02-28T00:00"), _ns("2026-03-18T00:00"), truth, noise_mm=0.1, zero_offset_mm=5.0)
    csv = write_series_csv(tmp_path / "cam.csv", t, v)
    window.open_campaign(processed_copy)
    monkeypatch.setattr(ImportCameraDialog, "exec", lambda self: ImportCameraDialog.Accepted)
    monkeypatch.setattr(ImportCameraDialog, "values", lambda self: {"file": str(csv), "name": "cam", "reflector": "M3",
                                                                   "timezone": "UTC", "positive": "up"})
    window.commands.import_camera()
    wait_job(qtbot, window)
    assert window.tree.item_for("series", "cam") is not None
    window.commands.crossval()
    wait_job(qtbot, window)
    cv = window.camera_view.result
    assert cv is not None and cv.n_pairs == 3 and not cv.has_statistics  # 3 pairs: too few for statistics
    assert window.tabs.currentWidget() is window.camera_view
    out = tmp_path / "r.pdf"
    monkeypatch.setattr("app.gui.commands.ask_save_path", lambda *a: out)
    window.commands.write_report()
    wait_job(qtbot, window)
    assert out.stat().st_size > 10_000 and out.read_bytes()[:4] == b"%PDF"
    detail = tmp_path / "detail.pdf"
    monkeypatch.setattr("app.gui.commands.ask_save_path", lambda *a: detail)
    window.commands.write_report(detail=True)  # Reports ▸ Write report with the appendix
    wait_job(qtbot, window)
    assert detail.stat().st_size > out.stat().st_size
    csv_out = tmp_path / "d.csv"
    monkeypatch.setattr("app.gui.commands.ask_save_path", lambda *a: csv_out)
    window.commands.export_csv()
    wait_job(qtbot, window)
    assert csv_out.read_text().startswith("epoch,datetime,reflector,displacement_mm,sigma_mm,flags")
    assert not errors


def test_long_work_can_be_cancelled_and_errors_never_freeze(window, qtbot, errors):
    import time

    from common.errors import InputError

    def slow(progress):
        for k in range(1000):
            progress(k / 1000, f"step {k}")
            time.sleep(0.01)

    window.run_job("Slow work", slow)
    qtbot.waitUntil(lambda: window.progress.isVisible() and window.progress.value() > 0, timeout=5000)
    assert window.cancel_btn.isVisible() and window.statusBar().currentMessage().startswith("Slow work: step")
    window.cancel_btn.click()
    assert window.statusBar().currentMessage() == "Slow work: cancelling…"
    assert window.cancel_btn.text() == "Cancelling…" and not window.cancel_btn.isEnabled()
    wait_job(qtbot, window, 5000)
    assert not errors and window.statusBar().currentMessage() == "Slow work: cancelled"
    assert not window.progress.isVisible() and not window.cancel_btn.isVisible()

    def fails(progress):
        raise InputError("x.laz: not a scan; check the file")

    window.run_job("Failing work", fails)
    wait_job(qtbot, window, 5000)
    assert errors[-1] == ("Failing work", "x.laz: not a scan; check the file")
    assert window.statusBar().currentMessage() == "Failing work failed: x.laz: not a scan; check the file"

    def bug(progress):
        raise ZeroDivisionError("oops")

    window.run_job("Buggy work", bug)
    wait_job(qtbot, window, 5000)
    assert "bug" in errors[-1][1] and "Traceback" not in errors[-1][1]


def test_3d_view_says_why_it_is_missing_offscreen(window):
    from PySide6.QtGui import QGuiApplication

    if QGuiApplication.platformName() == "offscreen":
        assert not window.cloud_view.show_btn.isEnabled()


def test_limits_reflectors_and_parameters_from_the_menus(window, processed_copy, monkeypatch, errors):
    from app.gui.dialogs import SetLimitDialog

    answers = iter(["M5b", "2026-03-20", "2000", "not-a-date"])
    monkeypatch.setattr("app.gui.commands.QInputDialog.getText", lambda *a, **k: (next(answers), True))
    monkeypatch.setattr(SetLimitDialog, "exec", lambda self: SetLimitDialog.Accepted)
    monkeypatch.setattr(SetLimitDialog, "values", lambda self: {"reflector": self.target.currentData(),
                                                                "rule": "abs:3,5"})
    monkeypatch.setattr("app.gui.commands.QInputDialog.getItem", lambda *a, **k: ("min_points", True))
    window.open_campaign(processed_copy)
    window.tree.select_key("reflector", "M3")
    window.commands.set_limit()
    window.tree.select_key("reflector", "M5")
    window.commands.replace_reflector()
    window.commands.set_parameter()
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.limit_for("M3").rule == "abs:3,5"
        assert c.reflector("M5b").replaces == "M5" and c.reflector("M5").retired
        assert c.settings()["min_points"] == 2000
    assert window.tree.item_for("reflector", "M5b") is not None
    before = snapshot(processed_copy)
    window.tree.select_key("reflector", "M4")
    window.commands.retire_reflector()  # "not-a-date"
    assert "not ISO 8601" in errors[-1][1] and snapshot(processed_copy) == before


def test_welcome_opens_the_demo_campaign(window, processed_copy):
    window.demo_dir = processed_copy  # a built demo campaign is opened directly
    window.open_demo()
    assert window.state.folder == processed_copy
    assert window.stack.currentWidget() is window.tabs


def test_field_sheet_check_stations_and_scanner_from_the_menus(window, processed_copy, tmp_path, qtbot, monkeypatch,
                                                               errors):
    from app.gui import commands

    window.open_campaign(processed_copy)
    window.state.select(epoch="2026-03-09")
    sheet = tmp_path / "sheet.pdf"
    monkeypatch.setattr(commands, "ask_save_path", lambda *a, **k: sheet)
    window.commands.field_sheet()
    wait_job(qtbot, window)
    assert sheet.read_bytes().startswith(b"%PDF")
    window.commands.check_selected()
    wait_job(qtbot, window)
    dlg = window.commands.check_dialog
    assert dlg.table.rowCount() == 9 and "complete" in dlg.summary.text()
    assert not dlg.save_btn.isEnabled()
    dlg.close()
    window.commands.evaluate_stations(8.0, 1.5)
    wait_job(qtbot, window)
    view = window.stations_view
    assert window.tabs.currentWidget() is view
    assert view.advice is not None and view.table.rowCount() > 0
    assert float(view.table.item(0, 3).text()) > 0
    from PySide6.QtWidgets import QInputDialog

    monkeypatch.setattr(QInputDialog, "getItem", staticmethod(lambda *a, **k: ("Trimble X7", True)))
    window.commands.choose_scanner()
    wait_job(qtbot, window)
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.profile.name == "Trimble X7"
    assert not errors


def test_fleet_page_lists_the_bridges_and_opens_one(window, processed_copy, tmp_path, qtbot, errors):
    import shutil

    root = tmp_path / "fleet"
    root.mkdir()
    shutil.copytree(processed_copy, root / "bridge-a", symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    shutil.copytree(processed_copy, root / "bridge-b", symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    window.commands.open_fleet(str(root))
    wait_job(qtbot, window)
    view = window.commands.fleet_view
    assert view.table.rowCount() == 2 and "2 bridges" in view.summary.text()
    assert view.table.item(0, 1).text() in ("ok", "warning", "alarm")
    view.table.selectRow(1)
    view.open_btn.click()
    assert window.state.is_open and str(window.state.folder).endswith(view.folders[1].split("/")[-1])
    assert not errors


def test_analysis_tab_and_event_overlay(window, processed_copy, tmp_path, qtbot, errors):
    from projects.series.environment import add_event

    with Campaign.open(processed_copy) as c:
        add_event(c, date="2026-03-12", kind="construction", label="slab")
    window.open_campaign(processed_copy)
    assert window.displacements.context is not None and len(window.displacements.context.events) == 1
    window.commands.run_analysis()
    wait_job(qtbot, window)
    view = window.analysis_view
    assert window.tabs.currentWidget() is view and view.table.rowCount() == 5
    assert "1 event" in view.info.text()
    assert not errors


def test_every_tab_fits_a_1366x768_screen(window, processed_copy, qtbot):
    from app.gui.main_window import SMALL_SCREEN
    from tests.app.gui.helpers import controls_out_of_reach

    window.resize(*SMALL_SCREEN)
    assert window.minimumSizeHint().width() <= SMALL_SCREEN[0]  # the welcome page
    window.open_campaign(processed_copy)
    window.state.select(epoch="2026-03-09", reflector="M3")
    for name, _title in window.TABS:
        window.state.request_view(name)
        qtbot.wait(30)
        hint = window.minimumSizeHint()
        assert hint.width() <= SMALL_SCREEN[0] and hint.height() <= SMALL_SCREEN[1], (name, hint)
        assert controls_out_of_reach(window) == [], name
    title = window.map_view.title  # the long title elides instead of widening the window; its tooltip has it all
    assert window.map_view.items and title.minimumSizeHint().width() < 200 and title.toolTip() == title.full_text()


def test_the_new_epochs_date_is_the_scan_files_own_time(qtbot, tmp_path):
    from pathlib import Path

    from app.gui.dialogs import AddEpochDialog
    from app.gui.state.folders import LastFolders

    data = Path(__file__).resolve().parents[2] / "data" / "las"
    dlg = AddEpochDialog(None, LastFolders({}, fallback=str(tmp_path)))
    qtbot.addWidget(dlg)
    dlg.coarse.edit.setText(str(data / "simple1_4.las"))
    assert dlg.values()["datetime"].startswith("2012-01-13T00:00") and "creation day" in dlg.when_source.text()
    assert dlg.values()["label"] == "2012-01-13"
    dlg.coarse.edit.setText(str(data / "test1_4.las"))  # another file: its points' GPS time
    assert dlg.values()["datetime"].startswith("2014-") and "GPS time" in dlg.when_source.text()
    dlg.when.setDateTime(dlg.when.dateTime().addDays(3))  # set by hand: kept from now on
    by_hand = dlg.values()["datetime"]
    dlg.coarse.edit.setText(str(data / "simple1_4.las"))
    assert dlg.values()["datetime"] == by_hand and dlg.when_source.text() == "set by hand"

"""Issue 41, round 2, in the application: nothing heavy on the interface thread, no stale words, the time zone.

What runs where is checked structurally (no timing here: bench/bench_gui_latency.py measures the interface's
longest pause through a weekly visit): every heavy action's work and the drawing it prepares run off the
interface thread, and the views only hand the result over.
"""
from __future__ import annotations

import threading

import pytest

from app.gui import actions
from projects.store.campaign import Campaign
from tests.app.gui.conftest import wait_job
from tests.app.gui.helpers import FileChooser, answer, menu_action

pytestmark = pytest.mark.gui

#: The actions that read scans, compute or write files: never on the interface thread.
HEAVY = ("create_campaign", "add_epoch", "add_fine", "inspect", "epoch_cloud", "change_cloud", "report", "process",
         "check", "plan")


@pytest.fixture
def threads(monkeypatch):
    """Where each of :data:`HEAVY` (and the pictures and clouds prepared for the views) ran: name -> [main?]."""
    import app.gui.commands as commands

    seen: dict[str, list[bool]] = {}

    def spy(module, name):
        fn = getattr(module, name)

        def wrapped(*a, **k):
            seen.setdefault(name, []).append(threading.current_thread() is threading.main_thread())
            return fn(*a, **k)
        monkeypatch.setattr(module, name, wrapped)

    for name in HEAVY:
        spy(actions, name)
    spy(commands, "draw_inspection")
    spy(commands, "prepare_cloud")
    return seen


def test_heavy_actions_and_their_drawing_run_in_the_worker(window, field_copy, processed_copy, tmp_path, qtbot,
                                                          monkeypatch, threads):
    from app.gui.dialogs import NewCampaignDialog

    files = FileChooser(monkeypatch)
    camp = tmp_path / "new"
    answer(NewCampaignDialog, lambda d: (d.folder.edit.setText(str(camp)), d.name.setText("Threads"),
                                         d.layout_csv.edit.setText(str(field_copy / "layout.csv"))))
    menu_action(window, "File", "New campaign…").trigger()
    wait_job(qtbot, window)
    assert window.state.name == "Threads"
    window.open_campaign(processed_copy)
    window.state.select(epoch="2026-03-16", reflector="M3")
    menu_action(window, "Epoch", "Inspect the selected target's fine scan").trigger()
    wait_job(qtbot, window)
    assert window.fine_view.inspection.centroid.found and not window.fine_view.image.pixmap().isNull()
    # the 3-D view cannot draw offscreen: the cloud is prepared all the same, and its status line says what is drawn
    window.state.outputs.cloud.disconnect(window.cloud_view.set_cloud)
    clouds = []
    window.state.outputs.cloud.connect(clouds.append)
    window.commands.show_cloud("intensity")
    wait_job(qtbot, window)
    from app.gui.state.cloud_display import POINT_BUDGET

    assert clouds and clouds[0].drawn <= POINT_BUDGET and clouds[0].xyz.dtype.name == "float32"
    assert window.statusBar().currentMessage().startswith("3-D view: ")
    files.will_choose(tmp_path / "report.pdf")
    menu_action(window, "Reports", "Write report (PDF)…").trigger()
    wait_job(qtbot, window)
    assert (tmp_path / "report.pdf").stat().st_size > 0
    window.commands.process()
    wait_job(qtbot, window)
    ran = {name: where for name, where in threads.items()}
    assert {"create_campaign", "inspect", "epoch_cloud", "report", "process", "draw_inspection",
            "prepare_cloud"} <= set(ran), ran
    on_main = [name for name, where in ran.items() if any(where)]
    assert on_main == [], f"heavy work on the interface thread: {on_main}"


def test_the_report_shows_progress_from_its_start(window, processed_copy, tmp_path, qtbot, monkeypatch):
    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    said = []
    window.state.status.changed.connect(lambda m: said.append(m.text))
    files.will_choose(tmp_path / "r.pdf")
    window.commands.write_report()
    wait_job(qtbot, window)
    steps = [t for t in said if t.startswith("Writing the report: ")]
    # the report is written in a process of its own, which says "starting" until its first word
    steps = [t for t in steps if t != "Writing the report: starting"]
    assert steps and steps[0] == "Writing the report: reading the campaign", said
    assert any("reading epoch 2026-03-02" in t for t in steps[:4]), steps  # the campaign's reading reports as it goes


def test_a_failure_resets_the_progress_before_its_box(window, qtbot, errors, monkeypatch):
    from PySide6.QtWidgets import QMessageBox

    from common.errors import InputError

    seen = []

    def box(parent, title, text, *a, **k):  # what the window shows at the moment the error box opens
        seen.append((window.progress.isVisible(), window.progress.value(), window.cancel_btn.isVisible(),
                     window.cancel_btn.isEnabled(), text))
    monkeypatch.setattr(QMessageBox, "critical", staticmethod(box))

    def fails(progress):
        progress(0.1, "reading")
        raise InputError("the file ends early")
    window.run_job("Reading a scan", fails)
    wait_job(qtbot, window)
    assert seen == [(False, 0, False, False, "the file ends early")]
    assert window.statusBar().currentMessage() == "Reading a scan failed: the file ends early"


def test_an_outcome_line_stays_on_its_tab(window, processed_copy, qtbot):
    window.open_campaign(processed_copy)
    window.state.select(epoch="2026-03-16", reflector="M3")
    window.commands.show_fine()  # shows the fine-scan tab; its job ends with "…: done"
    wait_job(qtbot, window)
    assert window.tabs.currentWidget() is window.fine_view
    assert window.statusBar().currentMessage() == "Reading the window of M3 in 2026-03-16: done"
    window.tabs.setCurrentWidget(window.map_view)
    assert window.statusBar().currentMessage() == ""  # not lingering over the map
    window.state.status.started("Planning")  # a running job's line is the window's, whatever the tab
    window.tabs.setCurrentWidget(window.displacements)
    assert window.statusBar().currentMessage() == "Planning…"
    window.state.status.finished(ok=True)


def test_the_new_campaign_dialog_asks_the_time_zone(window, field_copy, tmp_path, qtbot, errors):
    from app.gui.dialogs import NewCampaignDialog, machine_zone

    shown = []
    camp = tmp_path / "berlin"

    def fill(d):
        shown.append(d.timezone.currentText())
        d.folder.edit.setText(str(camp))
        d.name.setText("Zoned")
        d.layout_csv.edit.setText(str(field_copy / "layout.csv"))
        d.timezone.setCurrentText("Europe/Berlin")
    answer(NewCampaignDialog, fill)
    menu_action(window, "File", "New campaign…").trigger()
    wait_job(qtbot, window)
    assert shown == [machine_zone()]  # the machine's zone unless chosen
    with Campaign.open(camp, writable=False) as c:
        assert c.timezone == "Europe/Berlin"
    assert window.zone_label.text() == "zone Europe/Berlin" and window.zone_label.isVisible()
    assert "Time zone" in window.details.toPlainText() and "Europe/Berlin" in window.details.toPlainText()
    # a zone nobody knows: one line, no campaign made
    bad = tmp_path / "mars"
    answer(NewCampaignDialog, lambda d: (d.folder.edit.setText(str(bad)), d.name.setText("Mars"),
                                         d.layout_csv.edit.setText(str(field_copy / "layout.csv")),
                                         d.timezone.setCurrentText("Mars/Olympus")))
    menu_action(window, "File", "New campaign…").trigger()
    wait_job(qtbot, window)
    assert errors[-1][0].startswith("Creating the campaign") and "Mars/Olympus" in errors[-1][1]
    assert "\n" not in errors[-1][1] and not (bad / "campaign.sqlite").exists()


def test_the_report_written_in_its_own_process_can_be_cancelled(window, processed_copy, tmp_path, qtbot, monkeypatch,
                                                                errors):
    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    said = []
    window.state.status.changed.connect(lambda m: said.append(m.text))
    files.will_choose(tmp_path / "r.pdf")
    window.commands.write_report()
    qtbot.waitUntil(lambda: any("reading epoch" in t for t in said), timeout=60_000)  # the child is at work
    window.cancel_btn.click()
    wait_job(qtbot, window)
    assert not errors and window.statusBar().currentMessage() == "Writing the report: cancelled"
    assert not (tmp_path / "r.pdf").exists()
    assert [p.name for p in tmp_path.iterdir() if "part" in p.name] == []  # nothing half-written left behind

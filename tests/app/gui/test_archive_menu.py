"""Campaign ▸ Archive processed scans… and Restore scans… (issue 44): a folder picker, a dry run's summary asked
before anything moves, the move in the worker with progress and cancel, errors as one line in a message box."""
from __future__ import annotations

import threading
from pathlib import Path

import pytest

from projects.store import archive
from projects.store.archive import archived_scans
from projects.store.campaign import Campaign
from tests.app.gui.conftest import wait_job
from tests.app.gui.helpers import FileChooser, menu_action
from tests.projects.campaign_helpers import snapshot

pytestmark = pytest.mark.gui


def scans_here(camp: Path) -> list[str]:
    return sorted(p.name for p in (camp / "scans").iterdir() if p.is_file() and not p.name.startswith("."))


@pytest.fixture
def asked(monkeypatch):
    """The questions the window asked (title, text), answered by ``asked.answers`` in turn (default Yes)."""
    from PySide6.QtWidgets import QMessageBox

    class Asked(list):
        answers: list = []

    questions = Asked()

    def question(parent, title, text, *a, **k):
        questions.append((title, text))
        return questions.answers.pop(0) if questions.answers else QMessageBox.Yes
    monkeypatch.setattr(QMessageBox, "question", staticmethod(question))
    infos: list = []
    monkeypatch.setattr(QMessageBox, "information", staticmethod(lambda p, title, text, *a, **k: infos.append(text)))
    questions.infos = infos
    return questions


def settle(qtbot, window, until) -> None:
    """Wait for the chained jobs (the dry run, then the move) to end."""
    qtbot.waitUntil(lambda: until() and not window.jobs.busy, timeout=180_000)
    wait_job(qtbot, window)


def test_archive_asks_with_the_dry_run_then_moves_in_the_worker(window, processed_copy, disk, qtbot, monkeypatch,
                                                                asked, errors):
    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    where = []
    real = archive.archive_scans
    monkeypatch.setattr("app.gui.actions.archive_scans", lambda *a, **k: (
        where.append((k.get("dry_run", False), threading.current_thread() is threading.main_thread())), real(*a, **k))[1])
    said = []
    window.state.status.changed.connect(lambda m: said.append(m.text))
    files.will_choose(disk)
    menu_action(window, "Campaign", "Archive processed scans…").trigger()
    settle(qtbot, window, lambda: len(scans_here(processed_copy)) == 0)
    assert errors == []
    (title, text), = asked
    assert title == "Archive processed scans" and text.startswith("Move 6 scan(s) of 3 visit(s) (") and str(disk) in text
    assert "free" in text and "Restore scans" in text
    assert where == [(True, False), (False, False)]  # the dry run, then the move: both in the worker
    assert len(list(disk.iterdir())) == 6
    assert any(t.startswith("Archiving scans: archiving scans/") for t in said), said  # its progress, scan by scan
    assert window.statusBar().currentMessage().startswith("archived 6 scan(s) of 3 visit(s) to ")
    with Campaign.open(processed_copy, writable=False) as c:
        assert len(archived_scans(c)) == 6


def test_saying_no_moves_nothing_and_nothing_to_archive_says_so(window, processed_copy, disk, qtbot, monkeypatch,
                                                               asked, errors):
    from PySide6.QtWidgets import QMessageBox

    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    before = snapshot(processed_copy)
    asked.answers.append(QMessageBox.No)
    files.will_choose(disk)
    menu_action(window, "Campaign", "Archive processed scans…").trigger()
    wait_job(qtbot, window)
    assert len(asked) == 1 and snapshot(processed_copy) == before and list(disk.iterdir()) == []
    assert window.statusBar().currentMessage() == "archive: nothing was moved"
    menu_action(window, "Campaign", "Archive processed scans…").trigger()  # the picker cancelled: nothing at all
    wait_job(qtbot, window)
    assert len(asked) == 1 and snapshot(processed_copy) == before
    with Campaign.open(processed_copy) as c:
        archive.archive_scans(c, disk, [e.label for e in c.epochs()])
    files.will_choose(disk)
    menu_action(window, "Campaign", "Archive processed scans…").trigger()
    wait_job(qtbot, window)
    assert asked.infos == ["Nothing to archive: every processed visit's scans are archived already."]
    assert errors == []


def test_a_bad_folder_is_one_line_in_a_message_box_and_changes_nothing(window, processed_copy, qtbot, monkeypatch,
                                                                      asked, errors):
    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    before = snapshot(processed_copy)
    files.will_choose(processed_copy / "scans")
    menu_action(window, "Campaign", "Archive processed scans…").trigger()
    wait_job(qtbot, window)
    (title, text), = errors
    assert title == "Looking at what to archive" and "\n" not in text
    assert "inside the campaign folder" in text and "nothing was changed" in text and "--to" not in text
    assert asked == [] and snapshot(processed_copy) == before


def test_cancel_stops_between_scans_and_leaves_a_whole_campaign(window, processed_copy, disk, qtbot, monkeypatch,
                                                               asked, errors):
    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    real = archive._archive_one
    calls = []

    def one_then_cancel(*a, **k):
        out = real(*a, **k)
        calls.append(out)
        if len(calls) == 1:
            window.jobs.cancel()  # as the Cancel button does, while the second scan waits its turn
        return out
    monkeypatch.setattr(archive, "_archive_one", one_then_cancel)
    files.will_choose(disk)
    menu_action(window, "Campaign", "Archive processed scans…").trigger()
    settle(qtbot, window, lambda: len(calls) >= 1)
    assert errors == [] and len(calls) == 1
    assert len(scans_here(processed_copy)) == 5 and len(list(disk.iterdir())) == 1
    assert "cancel" in window.statusBar().currentMessage().lower()
    with Campaign.open(processed_copy, writable=False) as c:
        assert len(archived_scans(c)) == 1
    from projects.results.integrity import verify_campaign

    with Campaign.open(processed_copy, writable=False) as c:
        assert [f.line() for f in verify_campaign(c) if not f.is_note] == []


def test_restore_asks_for_the_folder_when_the_archive_disk_is_mounted_elsewhere(window, processed_copy, disk, qtbot,
                                                                                 monkeypatch, asked, errors):
    with Campaign.open(processed_copy) as c:
        archive.archive_scans(c, disk, [e.label for e in c.epochs()])
    elsewhere = disk.with_name("mounted-elsewhere")
    disk.rename(elsewhere)
    window.open_campaign(processed_copy)
    files = FileChooser(monkeypatch)
    files.will_choose(elsewhere)
    menu_action(window, "Campaign", "Restore scans…").trigger()
    settle(qtbot, window, lambda: len(scans_here(processed_copy)) == 6)
    assert errors == []
    (t1, first), (t2, second) = asked
    assert t1 == t2 == "Restore scans"
    assert first.startswith(f"The archived scans are not at {disk} ") and "Choose the folder" in first
    assert second.startswith("Bring back 6 scan(s) of 3 visit(s) (") and f"from {elsewhere.resolve()}" in second
    assert list(elsewhere.iterdir()) == []
    assert window.statusBar().currentMessage() == "brought back 6 scan(s) of 3 visit(s), each checked against its " \
                                                  "checksum"
    with Campaign.open(processed_copy, writable=False) as c:
        assert archived_scans(c) == [] and sum(e.action == "relocate" for e in c.log()) == 6


def test_restore_from_the_recorded_place_and_a_changed_copy_in_one_line(window, processed_copy, disk, qtbot,
                                                                        monkeypatch, asked, errors):
    with Campaign.open(processed_copy) as c:
        archive.archive_scans(c, disk, [e.label for e in c.epochs()])
        victim = Path(archived_scans(c)[0].place)  # the first to come back
    victim.chmod(0o644)
    data = bytearray(victim.read_bytes())
    data[-1] ^= 0xFF
    victim.write_bytes(bytes(data))
    window.open_campaign(processed_copy)
    before = snapshot(processed_copy)
    menu_action(window, "Campaign", "Restore scans…").trigger()
    settle(qtbot, window, lambda: bool(errors))
    (title, text), = errors
    assert title == "Restoring scans" and "\n" not in text and victim.name in text and "it stays archived" in text
    (_, question), = asked
    assert question.startswith("Bring back 6 scan(s) of 3 visit(s)") and f"from {disk}" in question
    assert snapshot(processed_copy) == before

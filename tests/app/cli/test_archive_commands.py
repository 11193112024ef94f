"""'bridgesurvey archive': the scans of processed visits moved to another disk and back, as a surveyor runs it."""
from __future__ import annotations

import errno
import os
import shutil
import sqlite3
import stat
from pathlib import Path

import pytest

from projects.store import archive, journal, schema
from projects.store.archive import archived_scans
from projects.store.campaign import DB_NAME, Campaign
from projects.store.imports import BY_VISIT
from tests.projects.campaign_helpers import snapshot
from tests.projects.store.test_faults import one_line, run
from tests.projects.store.test_integrity import back_to_version_12

FIRST, SECOND, LAST = "2026-03-02", "2026-03-09", "2026-03-16"


def scans_here(camp: Path) -> list[str]:
    return sorted(p.name for p in (camp / "scans").iterdir() if p.is_file() and not p.name.startswith("."))


def links(camp: Path) -> list[str]:
    d = camp / "scans" / BY_VISIT
    return sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_symlink()) if d.is_dir() else []


def displacements_csv(capsys, camp: Path) -> str:
    rc, out, _ = run(capsys, "displacements", camp, "--format", "csv")
    assert rc == 0
    return out


def test_archive_status_verify_process_restore_as_a_surveyor_runs_them(processed_copy, disk, capsys):
    camp = processed_copy
    stored = scans_here(camp)
    assert len(stored) == 6 and links(camp)
    before_csv = displacements_csv(capsys, camp)
    before = snapshot(camp)

    rc, out, _ = run(capsys, "archive", camp, "--to", disk, "--dry-run")
    assert rc == 0 and "would move" in out and "nothing was changed" in out and "freeing" in out
    assert snapshot(camp) == before and list(disk.iterdir()) == []

    rc, out, _ = run(capsys, "archive", camp, "--to", disk)
    assert rc == 0
    for label in (FIRST, SECOND, LAST):
        assert f"{label}: moved 2 scan(s)" in out and str(disk) in out
    assert "archived 6 scan(s) of 3 visit(s)" in out and "MB freed" in out
    assert scans_here(camp) == [] and links(camp) == []
    assert sorted(p.name for p in disk.iterdir()) == stored
    assert all(not (p.stat().st_mode & stat.S_IWUSR) for p in disk.iterdir())  # read-only, as in the campaign

    rc, out, _ = run(capsys, "archive", camp, "--to", disk)  # idempotent
    assert rc == 0 and "archived 0 scan(s)" in out and "nothing to archive" in out

    rc, out, _ = run(capsys, "status", camp)
    assert rc == 0 and f"0 scan(s) in the campaign folder, 6 archived in {disk}" in out and "MB on disk" in out
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 0 and "no problem found" in out
    # stage 2 and what is made of it work without the scans
    assert displacements_csv(capsys, camp) == before_csv
    rc, out, _ = run(capsys, "process", camp)
    assert rc == 0
    assert run(capsys, "report", camp, "--out", camp.parent / "report.pdf")[0] == 0

    # the archive disk is away: verify names the scans as archived, not checked, and still passes
    away = disk.with_name("unplugged")
    disk.rename(away)
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 0 and out.count("ARCHIVED ") == 6 and "not reachable now: not checked" in out
    assert "6 archived scan(s) not reachable, not checked" in out
    away.rename(disk)

    # a stage-1 parameter changes: processing says, per visit, which scans it needs back and how
    assert run(capsys, "settings", camp, "min_points", "1200")[0] == 0
    rc, out, err = run(capsys, "process", camp)
    assert rc == 1
    for label in (FIRST, SECOND, LAST):  # each visit's row says which scans, where, and the command
        assert f"epoch {label}: processing it again (stage 1" in out
    assert f"archived to {disk}" in out and f"'bridgesurvey archive {camp} --restore --epoch {FIRST}'" in out
    assert all(name in out for name in stored)
    # and the error is one line for them all
    assert err.count("\n") == 1 and err.startswith(f"bridgesurvey: error: 3 epoch(s) ({FIRST} … {LAST}) need scans "
                                                    "archived out of the campaign folder"), err
    assert f"'bridgesurvey archive {camp} --restore'" in err
    assert displacements_csv(capsys, camp) == before_csv  # the stored values stay, served

    rc, out, _ = run(capsys, "archive", camp, "--restore", "--epoch", FIRST)
    assert rc == 0 and f"{FIRST}: brought back 2 scan(s)" in out and "checked against its checksum" in out
    assert len(scans_here(camp)) == 2 and len(links(camp)) == 2 and len(list(disk.iterdir())) == 4
    rc, out, err = run(capsys, "process", camp, "--epoch", FIRST)
    assert rc == 0 and "measured" in out

    rc, out, _ = run(capsys, "archive", camp, "--restore")
    assert rc == 0 and "brought back 4 scan(s) of 2 visit(s)" in out
    assert scans_here(camp) == stored and len(links(camp)) == 6 and list(disk.iterdir()) == []
    assert run(capsys, "process", camp)[0] == 0
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 0 and "no problem found" in out
    with Campaign.open(camp, writable=False) as c:
        assert archived_scans(c) == []
        actions = [e.action for e in c.log()]
        assert actions.count("archive") == 6 and actions.count("restore") == 6


def test_archive_before_a_date_moves_only_the_older_processed_visits(processed_copy, disk, capsys):
    rc, out, _ = run(capsys, "archive", processed_copy, "--to", disk, "--before", SECOND)
    assert rc == 0 and f"{FIRST}: moved 2 scan(s)" in out and SECOND not in out and LAST not in out
    assert len(scans_here(processed_copy)) == 4


def test_a_visit_not_processed_is_not_archived_and_says_why(processed_copy, disk, capsys):
    assert run(capsys, "settings", processed_copy, "min_points", "1200")[0] == 0
    rc, out, _ = run(capsys, "archive", processed_copy, "--to", disk)
    assert rc == 0 and f"{FIRST}: not archived: stage 1 not up to date" in out and "archived 0 scan(s)" in out
    assert len(scans_here(processed_copy)) == 6


def test_compare_and_the_3d_view_need_the_scans_back(processed_copy, disk, capsys):
    assert run(capsys, "archive", processed_copy, "--to", disk, "--before", SECOND)[0] == 0
    rc, _, err = run(capsys, "compare", processed_copy, "--from", FIRST, "--to", LAST, "--method", "c2c",
                     "--out", processed_copy.parent / "cmp")
    assert rc == 1
    one_line(err, f"epoch {FIRST}: the whole-scan comparison needs the scan(s)", "--restore")
    from projects.outputs.inspection import epoch_cloud
    from projects.store.errors import ScansArchivedError

    with Campaign.open(processed_copy, writable=False) as c, pytest.raises(ScansArchivedError, match="the 3-D view"):
        epoch_cloud(c, FIRST)


def test_archive_for_scripts_and_options_that_do_not_go_together(processed_copy, disk, capsys):
    import json

    rc, out, _ = run(capsys, "archive", processed_copy, "--to", disk, "--dry-run", "--json")
    doc = json.loads(out)
    assert rc == 0 and doc["dry_run"] and len(doc["scans"]) == 6 and doc["not_archived"] == []
    assert doc["bytes"] == sum(s["size"] for s in doc["scans"]) > 0 and list(disk.iterdir()) == []
    before = snapshot(processed_copy)
    for argv, words in ((["--restore", "--to", disk], "takes no --to"), (["--to", disk, "--epoch", FIRST], "--restore"),
                        ([], "--to DEST")):
        rc, _, err = run(capsys, "archive", processed_copy, *argv)
        assert rc == 1
        one_line(err, words)
    assert snapshot(processed_copy) == before


# ---------------------------------------------------------------------------------------------- bad destinations
def refused(capsys, camp: Path, dest, *words: str) -> None:
    before = snapshot(camp)
    rc, out, err = run(capsys, "archive", camp, "--to", dest)
    assert rc == 1 and out == ""
    one_line(err, str(dest), "nothing was changed", *words)
    assert snapshot(camp) == before


def test_a_missing_a_file_or_an_inside_destination_is_one_line_and_changes_nothing(processed_copy, tmp_path, capsys):
    refused(capsys, processed_copy, tmp_path / "not-mounted", "no such folder")
    (tmp_path / "a-file").write_text("x")
    refused(capsys, processed_copy, tmp_path / "a-file", "is a file")
    inside = processed_copy / "old-scans"
    inside.mkdir()
    refused(capsys, processed_copy, inside, "inside the campaign folder")
    refused(capsys, processed_copy, processed_copy, "inside the campaign folder")
    refused(capsys, processed_copy, processed_copy / "scans" / "..", "inside the campaign folder")


def test_an_unwritable_destination_is_one_line_and_changes_nothing(processed_copy, disk, capsys, monkeypatch):
    real_open = os.open

    def refusing(path, *args, **kw):  # the archive disk mounted read-only: what the system says (even to root)
        if Path(path).parent == disk:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real_open(path, *args, **kw)

    monkeypatch.setattr(os, "open", refusing)
    refused(capsys, processed_copy, disk, "cannot write into this folder", "Permission denied")


def test_a_full_destination_is_one_line_and_changes_nothing(processed_copy, disk, capsys, monkeypatch):
    monkeypatch.setattr("common.files.free_bytes", lambda p: 4096)
    before = snapshot(processed_copy)
    rc, out, _ = run(capsys, "archive", processed_copy, "--to", disk, "--dry-run")
    assert rc == 0 and f"{disk} has 0.0 MB free: not enough" in out and "nothing was changed" in out
    rc, out, err = run(capsys, "archive", processed_copy, "--to", disk)
    assert rc == 1 and out == ""
    one_line(err, "no space left on the device holding", str(disk))
    assert snapshot(processed_copy) == before and list(disk.iterdir()) == []


def test_a_disk_filling_during_a_copy_keeps_the_scan_and_leaves_no_partial_copy(processed_copy, disk, capsys,
                                                                                  monkeypatch):
    import builtins

    real_open = builtins.open

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def write(self, block):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    def filling(path, mode="r", *args, **kw):
        fh = real_open(path, mode, *args, **kw)
        return Full(fh) if "w" in mode and Path(path).parent == disk else fh

    monkeypatch.setattr(builtins, "open", filling)
    before = snapshot(processed_copy)
    rc, _, err = run(capsys, "archive", processed_copy, "--to", disk)
    assert rc == 1
    one_line(err, "no space left on the device holding", str(disk))
    assert snapshot(processed_copy) == before and list(disk.iterdir()) == []


def test_restore_with_the_archive_disk_away_is_one_line_and_changes_nothing(processed_copy, disk, capsys):
    assert run(capsys, "archive", processed_copy, "--to", disk)[0] == 0
    disk.rename(disk.with_name("away"))
    before = snapshot(processed_copy)
    rc, _, err = run(capsys, "archive", processed_copy, "--restore")
    assert rc == 1
    one_line(err, str(disk), "not there", "connect the archive disk", "nothing was changed")
    assert snapshot(processed_copy) == before


def test_a_changed_archived_copy_is_found_by_verify_and_never_restored(processed_copy, disk, capsys):
    assert run(capsys, "archive", processed_copy, "--to", disk, "--before", SECOND)[0] == 0
    victim = sorted(disk.iterdir())[0]
    victim.chmod(0o644)
    data = bytearray(victim.read_bytes())
    data[-1] ^= 0xFF
    victim.write_bytes(bytes(data))
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and f"its archived copy {victim} changed since its import" in out
    before = snapshot(processed_copy)
    rc, _, err = run(capsys, "archive", processed_copy, "--restore")
    assert rc == 1
    one_line(err, victim.name, "does not match the checksum recorded at its import", "it stays archived")
    assert snapshot(processed_copy) == before



# ---------------------------------------------------------------------------------------------- restore from elsewhere
@pytest.fixture
def moved_disk(processed_copy, disk, capsys) -> Path:
    """Every visit archived to ``disk``, then the disk mounted somewhere else (the recorded place gone)."""
    assert run(capsys, "archive", processed_copy, "--to", disk)[0] == 0
    elsewhere = disk.with_name("mounted-elsewhere")
    disk.rename(elsewhere)
    return elsewhere


def places(camp: Path) -> dict[str, str]:
    with Campaign.open(camp, writable=False) as c:
        return {a.file.epoch + "/" + a.name: str(Path(a.place).parent) for a in archived_scans(c)}


def test_restore_from_where_the_archive_disk_is_mounted_now(processed_copy, disk, moved_disk, capsys):
    camp = processed_copy
    before = snapshot(camp)
    rc, out, _ = run(capsys, "archive", camp, "--restore", "--from", moved_disk, "--dry-run")
    assert rc == 0 and "would bring back 6 scan(s) of 3 visit(s)" in out and f"from {moved_disk}" in out
    assert snapshot(camp) == before and len(list(moved_disk.iterdir())) == 6  # a dry run records nothing

    rc, out, _ = run(capsys, "archive", camp, "--restore", "--epoch", FIRST, "--from", moved_disk)
    assert rc == 0 and f"{FIRST}: brought back 2 scan(s)" in out and f"from {moved_disk}" in out
    assert len(scans_here(camp)) == 2 and len(links(camp)) == 2 and len(list(moved_disk.iterdir())) == 4
    # the other visits' scans were not asked for: their recorded place is untouched
    assert set(places(camp).values()) == {str(disk)}
    rc, out, _ = run(capsys, "archive", camp, "--restore", "--from", moved_disk)
    assert rc == 0 and "brought back 4 scan(s) of 2 visit(s)" in out
    assert len(scans_here(camp)) == 6 and list(moved_disk.iterdir()) == []
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 0 and "no problem found" in out
    with Campaign.open(camp, writable=False) as c:
        assert archived_scans(c) == []
        relocated = [e for e in c.log() if e.action == "relocate"]
    assert len(relocated) == 6


def test_the_new_place_is_recorded_before_the_copy_so_a_stopped_restore_needs_no_from(processed_copy, moved_disk,
                                                                                      capsys, monkeypatch):
    camp = processed_copy

    def stop(*a, **k):
        raise archive.CampaignError("the copy was stopped here")
    monkeypatch.setattr(archive, "_copy_checked", stop)
    rc, _, err = run(capsys, "archive", camp, "--restore", "--from", moved_disk)
    assert rc == 1
    one_line(err, "the copy was stopped here")
    assert set(places(camp).values()) == {str(moved_disk.resolve())}  # every scan's new place, checked, recorded
    with Campaign.open(camp, writable=False) as c:
        assert {Path(place).parent for _sha, place, _t in archive.archived_from_journal(c)} == {moved_disk.resolve()}
    monkeypatch.undo()
    rc, out, _ = run(capsys, "archive", camp, "--restore")  # the recorded place is the new one now
    assert rc == 0 and "brought back 6 scan(s) of 3 visit(s)" in out
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 0 and "no problem found" in out


def test_restore_from_a_wrong_folder_or_a_changed_copy_is_one_line_and_changes_nothing(processed_copy, moved_disk,
                                                                                       tmp_path, capsys):
    camp = processed_copy
    before = snapshot(camp)
    rc, _, err = run(capsys, "archive", camp, "--restore", "--from", tmp_path / "nowhere")
    assert rc == 1
    one_line(err, str(tmp_path / "nowhere"), "no such folder", "nothing was changed")
    empty = tmp_path / "empty"
    empty.mkdir()
    rc, _, err = run(capsys, "archive", camp, "--restore", "--from", empty)
    assert rc == 1
    one_line(err, "not there nor in", str(empty), "--from FOLDER", "nothing was changed")
    victim = sorted(moved_disk.iterdir())[-1]
    victim.chmod(0o644)
    data = bytearray(victim.read_bytes())
    data[-1] ^= 0xFF
    victim.write_bytes(bytes(data))
    rc, _, err = run(capsys, "archive", camp, "--restore", "--from", moved_disk)
    assert rc == 1
    one_line(err, str(victim), "does not match the checksum recorded at its import", "nothing was changed")
    rc, _, err = run(capsys, "archive", camp, "--to", tmp_path, "--from", moved_disk)
    assert rc == 1
    one_line(err, "--from goes with --restore")
    assert snapshot(camp) == before and len(list(moved_disk.iterdir())) == 6

# ---------------------------------------------------------------------------------------------- repair, schema
def test_a_database_older_than_the_archive_run_is_repaired_not_taken_for_lost(processed_copy, disk, capsys):
    old_db = processed_copy.parent / "backup.sqlite"
    shutil.copy(processed_copy / DB_NAME, old_db)
    assert run(capsys, "archive", processed_copy, "--to", disk, "--before", SECOND)[0] == 0
    shutil.copy(old_db, processed_copy / DB_NAME)  # the backup of last week restored over the folder
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and out.count("the journal of imports has it archived to") == 2 and "repair" in out
    rc, out, _ = run(capsys, "repair", processed_copy)
    assert out.count("recorded again as archived to") == 2
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 0 and "no problem found" in out
    assert run(capsys, "archive", processed_copy, "--restore")[0] == 0
    assert len(scans_here(processed_copy)) == 6


def test_a_campaign_of_version_12_migrates_and_archives(processed_copy, disk, capsys):
    conn = sqlite3.connect(processed_copy / DB_NAME)
    back_to_version_12(conn)
    conn.commit()
    conn.close()
    with Campaign.open(processed_copy) as c:
        assert schema.version_of(c.conn) == schema.SCHEMA_VERSION == 13 and archived_scans(c) == []
        assert [r[1] for r in c.conn.execute("PRAGMA table_info(archived_files)")] == ["sha256", "place", "archived"]
    assert run(capsys, "archive", processed_copy, "--to", disk)[0] == 0
    with Campaign.open(processed_copy, writable=False) as c:
        assert len(archived_scans(c)) == 6


# ---------------------------------------------------------------------------------------------- interrupted
class Stop(BaseException):
    """What a kill does to the run at that point (nothing after it happens)."""


def whole(camp: Path, capsys) -> None:
    """A campaign an interrupted archive left: opens, verifies, and every scan is here or at a checked copy."""
    with Campaign.open(camp, writable=False) as c:
        assert c.integrity_check() == "ok"
        moved = {a.file.stored_path: a for a in archived_scans(c)}
        for e in c.epochs():
            for f in c.files(e.label, setup=None):
                here = (camp / f.stored_path).is_file()
                assert here or (f.stored_path in moved and Path(moved[f.stored_path].place).is_file())
    rc, out, _ = run(capsys, "verify", camp)
    problems = [ln for ln in out.splitlines()[:-1] if not ln.startswith("TEMPORARY ")]  # the next writer removes
    assert rc in (0, 3) and not problems, out


def stop_at(monkeypatch, stop: tuple, where: str, disk: Path, camp: Path) -> None:
    """Make the ``nth`` counted call of ``owner.name`` raise :class:`Stop` (``stop``: an entry of the tables below)."""
    owner, name, counted, nth = stop
    real = getattr(owner, name)
    calls = {"n": 0}

    def stopping(*a, **kw):
        if counted(disk, camp, a):
            calls["n"] += 1
            if calls["n"] == nth:
                raise Stop(where)
        return real(*a, **kw)

    monkeypatch.setattr(owner, name, stopping)


STOPS = {  # where a run is stopped: (owner, attribute, which calls count, the how-many-th counted call)
    "the first copy written, not yet renamed": (os, "replace", lambda disk, camp, a: Path(a[1]).parent == disk, 1),
    "the second copy in place, its journal line not written": (journal, "append", lambda disk, camp, a: True, 2),
    "the third move's transaction": (Campaign, "log_action", lambda disk, camp, a: a[2] == "archive", 3),
    "the fourth recorded, still in the campaign": (archive, "_unlink_visit_links", lambda disk, camp, a: True, 4),
    "removing the fifth scan": (Path, "unlink", lambda disk, camp, a: a[0].parent == camp / "scans", 5),
}


@pytest.mark.parametrize("where", list(STOPS))
def test_an_archive_run_stopped_at_any_step_leaves_a_whole_campaign_archived_again(processed_copy, disk, capsys,
                                                                                   monkeypatch, where):
    from app.cli.main import main

    stop_at(monkeypatch, STOPS[where], where, disk, processed_copy)
    with pytest.raises(Stop):
        main(["archive", str(processed_copy), "--to", str(disk)])
    monkeypatch.undo()
    whole(processed_copy, capsys)
    rc, out, _ = run(capsys, "archive", processed_copy, "--to", disk)
    assert rc == 0 and scans_here(processed_copy) == [] and links(processed_copy) == []
    assert not [p for p in disk.iterdir() if p.name.startswith(".")]
    whole(processed_copy, capsys)
    with Campaign.open(processed_copy, writable=False) as c:
        assert len(archived_scans(c)) == 6
    archived = [e for e in journal.entries(processed_copy) if e.get("kind") == "archive"]
    assert len({e["sha256"] for e in archived}) == 6


RESTORE_STOPS = {
    "the first scan copied back, not journaled": (archive, "_copy_checked", lambda disk, camp, a: True, 1),
    "the second journaled, still recorded as archived": (journal, "append", lambda disk, camp, a: True, 2),
    "the third's transaction": (Campaign, "log_action", lambda disk, camp, a: a[2] == "restore", 3),
    "the fourth back and recorded, its archived copy not yet removed":
        (Path, "unlink", lambda disk, camp, a: a[0].parent == disk, 4),
}


@pytest.mark.parametrize("where", list(RESTORE_STOPS))
def test_a_restore_stopped_at_any_step_leaves_a_whole_campaign_restored_again(processed_copy, disk, capsys,
                                                                              monkeypatch, where):
    from app.cli.main import main

    assert run(capsys, "archive", processed_copy, "--to", disk)[0] == 0
    stop_at(monkeypatch, RESTORE_STOPS[where], where, disk, processed_copy)
    with pytest.raises(Stop):
        main(["archive", str(processed_copy), "--restore"])
    monkeypatch.undo()
    whole(processed_copy, capsys)
    rc, out, _ = run(capsys, "archive", processed_copy, "--restore")
    assert rc == 0 and len(scans_here(processed_copy)) == 6 and len(links(processed_copy)) == 6
    assert list(disk.iterdir()) == [] and not [p for p in (processed_copy / "scans").iterdir()
                                                if p.name.startswith(".")]
    whole(processed_copy, capsys)
    with Campaign.open(processed_copy, writable=False) as c:
        assert archived_scans(c) == []


#: A child process that runs the command and kills itself (SIGKILL) at the nth call of one function, before or
#: after it: a kill -9 at a known point of the run, whatever the machine's speed.
KILLER = """
import importlib, os, signal, sys
spec, nth, when = sys.argv[1], int(sys.argv[2]), sys.argv[3]
module, _, path = spec.partition(":")
owner = importlib.import_module(module)
*parents, name = path.split(".")
for p in parents:
    owner = getattr(owner, p)
real = getattr(owner, name)
calls = [0]
def killing(*a, **kw):
    calls[0] += 1
    if calls[0] == nth and when == "before":
        os.kill(os.getpid(), signal.SIGKILL)
    out = real(*a, **kw)
    if calls[0] == nth and when == "after":
        os.kill(os.getpid(), signal.SIGKILL)
    return out
setattr(owner, name, killing)
from app.cli.main import main
sys.exit(main(sys.argv[4:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("spec, nth, when", [
    ("os:fsync", 3, "after"),                                     # a copy flushed, not yet renamed
    ("projects.store.archive:_copy_checked", 2, "after"),         # the second copy in place, not journaled
    ("projects.store.journal:append", 3, "after"),                # the third journaled, not recorded
    ("projects.store.campaign:Campaign.log_action", 4, "after"),  # inside the fourth move's transaction
    ("projects.store.archive:_unlink_visit_links", 5, "after"),   # the fifth's links gone, the scan still here
])
def test_kill_9_during_archive_leaves_a_campaign_that_opens_verifies_and_archives_again(processed_copy, disk,
                                                                                      capsys, spec, nth, when):
    import signal
    import subprocess
    import sys

    argv = ["archive", str(processed_copy), "--to", str(disk)]
    proc = subprocess.run([sys.executable, "-c", KILLER, spec, str(nth), when, *argv],
                          cwd=Path(__file__).resolve().parents[3], capture_output=True, text=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr  # killed where asked, not finished
    assert list(disk.iterdir())  # in the middle of the archive's work (a copy, whole or not, is there)
    whole(processed_copy, capsys)
    assert 0 < len(scans_here(processed_copy))
    assert run(capsys, "archive", processed_copy, "--to", disk)[0] == 0
    assert scans_here(processed_copy) == [] and links(processed_copy) == []
    assert not [p for p in disk.iterdir() if p.name.startswith(".")]
    whole(processed_copy, capsys)
    with Campaign.open(processed_copy, writable=False) as c:
        assert len(archived_scans(c)) == 6

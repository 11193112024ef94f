"""The store keeps everything and says what it holds: the lock's holder, migrations from every version,
digests on every result, nothing imported ever deleted, thin inputs given their word."""
from __future__ import annotations

import errno
import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from app.cli.main import main
from common.files import DiskFullError, atomic_output, sha256_of, write_atomic
from lidar.layout import read_layout_csv
from projects.processing.stages import stage1_jobs, stale_epochs
from projects.store import digests, journal, lock, schema
from projects.store.campaign import DB_NAME, Campaign
from projects.store.errors import CampaignError, CampaignLockedError
from tests.projects.campaign_helpers import snapshot

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def camp(field_copy, tmp_path):
    with Campaign.create(tmp_path / "camp", name="Integrity", layout=read_layout_csv(field_copy / "layout.csv")):
        pass
    return tmp_path / "camp"


# ---------------------------------------------------------------------------------------------- the lock
def test_the_lock_names_the_process_holding_it_now_and_since_when(camp):
    with Campaign.open(camp, writable=False):  # an earlier reader, finished: its line must not be blamed
        pass
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; from projects.store.campaign import Campaign\n"
         f"c = Campaign.open({str(camp)!r}, writable=False); print('open', flush=True); time.sleep(60)"],
        cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "open"
        with pytest.raises(CampaignLockedError) as err:
            Campaign.open(camp)
        msg = str(err.value)
        assert f"BridgeSurvey process {holder.pid} (" in msg and "holding it since" in msg and " UTC" in msg
        assert str(os.getpid()) not in msg and len(msg.splitlines()) == 1
    finally:
        holder.kill()
        holder.wait()
    with Campaign.open(camp):  # the kernel released it with the process
        pass


def test_a_stale_lock_file_is_no_lock_and_is_never_blamed(camp, monkeypatch):
    (camp / ".lock").write_text('{"pid": 999999, "start": 1, "taken": "2020-01-01T00:00:00+00:00", '
                                '"command": "bridgesurvey settings"}\nBridgeSurvey process 12345\n')
    with Campaign.open(camp):  # nobody holds it: opens
        with pytest.raises(CampaignLockedError, match=f"in use by BridgeSurvey process {os.getpid()} ") as err:
            Campaign.open(camp)
        assert "999999" not in str(err.value) and "12345" not in str(err.value)
        monkeypatch.setattr(lock, "lock_holders", lambda path: None)  # no /proc/locks: says it cannot tell
        with pytest.raises(CampaignLockedError, match="cannot tell which"):
            Campaign.open(camp)
    assert (camp / ".lock").read_text() == ""  # a writer leaves no line behind


# ---------------------------------------------------------------------------------------------- migrations
def _v1_database(folder: Path) -> None:
    (folder / "scans").mkdir(parents=True)
    conn = sqlite3.connect(folder / DB_NAME)
    with conn:
        conn.executescript(schema.SCHEMA_V1)
        conn.execute("INSERT INTO meta VALUES ('schema_version', '1')")
        conn.executemany("INSERT INTO meta VALUES (?, ?)", [("name", "Old bridge"), ("span_m", "40.0"),
                                                            ("settings", "{}"), ("created", "2025-01-01T00:00:00")])
        conn.execute("INSERT INTO reflectors(id, grp, x, y, z, diameter_m) VALUES ('M1', 'measurement', 1, 2, 3, 0.05)")
        conn.execute("INSERT INTO reflectors(id, grp, x, y, z, diameter_m) VALUES ('R1', 'reference', 0, 0, 3, 0.05)")
        conn.execute("INSERT INTO epochs VALUES ('e1', '2025-01-06T09:00:00+00:00', '', '2025-01-06T10:00:00')")
        conn.execute("INSERT INTO epoch_results VALUES ('e1', 'measured', 'h1', '2025-01-06T11:00:00')")
        conn.execute("INSERT INTO centroids VALUES ('e1', 'M1', 1, 1.0, 2.0, 3.0, '[[0,0,0],[0,0,0],[0,0,0]]', "
                     "900, 0.5, 0.9, 0.005, '[]')")
        conn.execute("INSERT INTO displacement_sets VALUES ('e1', 'e1', 'h2', '[0,0,1]', '[0,0,0]', '[\"R1\"]', "
                     "'auto', '[]', '2025-01-06T11:00:00')")
        conn.execute("INSERT INTO displacements VALUES ('e1', 'M1', 0.0, 0.0, 3.0, 3.0, '[]')")
    conn.close()


@pytest.mark.parametrize("version", range(1, schema.SCHEMA_VERSION))
def test_every_earlier_version_migrates_to_the_current_one_with_its_data(tmp_path, version):
    folder = tmp_path / f"v{version}"
    _v1_database(folder)
    conn = sqlite3.connect(folder / DB_NAME)
    schema.migrate(conn, 1, version)  # the campaign as that version of BridgeSurvey left it
    assert schema.version_of(conn) == version
    conn.close()
    with Campaign.open(folder, writable=False) as c:  # a reader upgrades it too
        assert schema.version_of(c.conn) == schema.SCHEMA_VERSION
        assert c.integrity_check() == "ok" and c.damaged_results() == []
        assert [e.label for e in c.epochs()] == ["e1"] and c.name == "Old bridge"
        assert c.result("e1").stage == "measured"  # its results are sealed by the digest migration, and served
        assert c.centroids("e1")["M1"].n_points == 900
        assert [d.displacement_m for d in c.displacements()] == [0.0]
        assert c.map_preview("e1") is None


def test_a_failing_migration_leaves_the_campaign_at_its_version(camp, monkeypatch):
    before = snapshot(camp)
    nxt = schema.SCHEMA_VERSION + 1
    monkeypatch.setattr(schema, "SCHEMA_VERSION", nxt)
    monkeypatch.setitem(schema.MIGRATIONS, nxt, "ALTER TABLE epochs ADD COLUMN weather TEXT;\n"
                                                "UPDATE no_such_table SET x = 1;")
    with pytest.raises(CampaignError, match=f"upgrade of the campaign from schema {nxt - 1} to {nxt} failed.*"
                                            f"unchanged at version {nxt - 1}"):
        Campaign.open(camp)
    assert snapshot(camp) == before  # the column added before the failure was rolled back with it

    def half(conn):
        conn.execute("ALTER TABLE epochs ADD COLUMN weather TEXT")
        raise sqlite3.OperationalError("simulated failure")
    monkeypatch.setitem(schema.MIGRATIONS, nxt, half)
    with pytest.raises(CampaignError, match="failed"):
        Campaign.open(camp, writable=False)
    assert snapshot(camp) == before


def back_to_version_12(conn: sqlite3.Connection) -> None:
    """Undo migration 13 (where archived scans went) of a current campaign."""
    conn.execute("DROP TABLE archived_files")
    conn.execute("UPDATE meta SET value = '12' WHERE key = 'schema_version'")


def back_to_version_11(conn: sqlite3.Connection) -> None:
    """Undo migrations 13 and 12 (the digests of input rows) of a current campaign."""
    back_to_version_12(conn)
    for g in digests.INPUTS.values():
        conn.execute(f"ALTER TABLE {g.table} DROP COLUMN {g.column}")
    conn.execute("UPDATE meta SET value = '11' WHERE key = 'schema_version'")


def _back_to_version_9(conn: sqlite3.Connection) -> None:
    """Undo migrations 12, 11 (the set-up tables and file columns) and 10 (the digests) of a current campaign."""
    back_to_version_11(conn)
    for table in ("setup_plans", "setup_previews", "setup_results"):
        conn.execute(f"DROP TABLE {table}")
    for column in ("setup", "frame"):
        conn.execute(f"ALTER TABLE files DROP COLUMN {column}")
    for table in digests.V10_TABLES:
        conn.execute(f"ALTER TABLE {table} DROP COLUMN digest")
    conn.execute("UPDATE meta SET value = '9' WHERE key = 'schema_version'")


def test_the_digest_migration_seals_an_existing_campaign(processed_copy):
    conn = sqlite3.connect(processed_copy / DB_NAME)
    _back_to_version_9(conn)
    conn.commit()
    conn.close()
    with Campaign.open(processed_copy) as c:
        assert schema.version_of(c.conn) == schema.SCHEMA_VERSION and c.damaged_results() == []
        labels = [e.label for e in c.epochs()]
        assert all(c.result(lab).stage == "measured" for lab in labels)
        assert all(c.displacement_set(lab) is not None for lab in labels)
        assert c.map_preview(labels[0]) is not None


# ---------------------------------------------------------------------------------------------- digests
def test_every_stored_result_is_sealed_and_a_damaged_one_is_stale(processed_copy):
    with Campaign.open(processed_copy) as c:
        labels = [e.label for e in c.epochs()]
        assert c.damaged_results() == []
        n_before = len(c.displacements())
        with c.transaction() as conn:  # a value changed behind the store's back (as a flipped byte would)
            conn.execute("UPDATE displacements SET displacement_m = displacement_m + 0.002 WHERE epoch = ?",
                         (labels[-1],))
            conn.execute("UPDATE map_previews SET annotations = replace(annotations, '\"rms_m\"', '\"rms_x\"') "
                         "WHERE epoch = ?", (labels[0],))
        assert set(c.damaged_results()) == {("displacement_sets", (labels[-1],)), ("map_previews", (labels[0],))}
        assert c.displacement_set(labels[-1]) is None and c.reference_checks(labels[-1]) == []
        assert {d.epoch for d in c.displacements()} == set(labels[:-1]) and len(c.displacements()) < n_before
        assert c.map_preview(labels[0]) is None
        assert set(c.damaged_results(pictures=False)) == {("displacement_sets", (labels[-1],))}
        # a picture decides no number: the plan and the centroids stand, 'process' plans again to remake it
        assert c.result(labels[0]) is not None and c.stored_plan(labels[0]) is not None
        assert c.preview_to_remake(labels[0]) and not c.preview_to_remake(labels[1])
        assert labels[0] not in stale_epochs(c)  # the quick look (status) does not read the previews
        jobs = stage1_jobs(c, labels[0])  # what 'process' runs: planned again from the coarse scan, not reused
        assert [(j.setup, j.stored_plan) for j in jobs] == [(1, None)]


def test_checking_a_whole_table_at_once_agrees_with_checking_each_group(processed_copy):
    with Campaign.open(processed_copy) as c:
        labels = [e.label for e in c.epochs()]
        with c.transaction() as conn:  # two values changed behind the store's back
            conn.execute("UPDATE centroids SET x = x + 0.001 WHERE epoch = ? AND reflector = 'M1'", (labels[1],))
            conn.execute("UPDATE displacements SET sigma_m = sigma_m * 2 WHERE epoch = ?", (labels[-1],))
        for table in digests.GROUPS:
            each = {k: digests.is_sound(c.conn, table, k) for k in digests.keys_of(c.conn, table)}
            assert digests.sound_groups(c.conn, table) == each, table
        assert not digests.sound_groups(c.conn, "epoch_results")[(labels[1],)]
        assert not digests.sound_groups(c.conn, "displacement_sets")[(labels[-1],)]
        assert sum(not ok for ok in digests.sound_groups(c.conn, "epoch_results").values()) == 1
        assert set(c.damaged_results()) == {("epoch_results", (labels[1],)), ("displacement_sets", (labels[-1],))}
        assert c.result(labels[1]) is None and c.result(labels[0]) is not None  # what the pass found, served


def test_every_epochs_check_verdict_read_at_once_is_each_ones(processed_copy):
    with Campaign.open(processed_copy) as c:
        labels = [e.label for e in c.epochs()]
        c.save_check_verdict(labels[0], setup=1, rescan={"M1": "few points"}, drifted=False)
        c.save_check_verdict(labels[1], setup=1, rescan={"M2": "not found"}, drifted=True)
        c.accept_check(labels[1])
        c.save_check_verdict(labels[2], setup=1, rescan={}, drifted=False)
        c.save_check_verdict(labels[2], setup=2, rescan={"R1": "grazing"}, drifted=False)
        each = {lab: v for lab in labels if (v := c.check_verdict(lab)) is not None}
        assert c.check_verdicts() == each and set(each) == set(labels[:3])
        assert each[labels[1]].accepted and each[labels[2]].rescan == ("R1",)


# ---------------------------------------------------------------------------------------------- nothing deleted
def test_opening_removes_temporary_files_only_never_an_imported_file(processed_copy):
    scans = processed_copy / "scans"
    stray = scans / "0123456789abcdef_restored.laz"
    stray.write_bytes(b"a file the database does not list")
    temp = scans / f".import-{'ab' * 16}"
    temp.write_bytes(b"half a copy")
    other_hidden = scans / ".keep-me"
    other_hidden.write_bytes(b"")
    (processed_copy / "camera").mkdir(exist_ok=True)
    (processed_copy / "camera" / "series.csv").write_text("time,mm\n")
    with Campaign.open(processed_copy) as c:
        assert c.unlisted_files() == ["camera/series.csv", "scans/0123456789abcdef_restored.laz"]
    assert stray.exists() and other_hidden.exists() and (processed_copy / "camera" / "series.csv").exists()
    assert not temp.exists()


def test_a_failed_import_takes_back_its_copy_and_journal_line(camp, field_copy):
    coarse = field_copy / "v0" / "coarse.laz"
    with Campaign.open(camp) as c:
        c.add_epoch("e1", "2026-03-02", coarse)
    before = snapshot(camp)
    src = field_copy / "v1" / "coarse.laz"
    with Campaign.open(camp) as c:  # SQLite fails the row as on a full disk
        c.conn.execute("CREATE TEMP TRIGGER full BEFORE INSERT ON log BEGIN "
                       "SELECT RAISE(FAIL, 'database or disk is full'); END")
        with pytest.raises(DiskFullError, match="no space left on the device holding .*campaign.sqlite: free "
                                                r"\d+ MB and run the command again"):
            c.add_epoch("e2", "2026-03-09", src)
    assert snapshot(camp) == before
    assert len(journal.entries(camp)) == 1


# ---------------------------------------------------------------------------------------------- disk full
def test_full_disk_in_an_output_is_one_line_and_leaves_no_file(tmp_path, monkeypatch):
    out = tmp_path / "report.pdf"
    with pytest.raises(DiskFullError, match=f"no space left on the device holding {out}: free \\d+ MB"):
        with atomic_output(out) as tmp:
            tmp.write_bytes(b"x" * 100)
            raise OSError(errno.ENOSPC, "No space left on device")
    assert list(tmp_path.iterdir()) == []
    import common.files

    monkeypatch.setattr(common.files.os, "replace", lambda *a: (_ for _ in ()).throw(OSError(errno.ENOSPC, "full")))
    with pytest.raises(DiskFullError):
        write_atomic(out, "text")
    assert list(tmp_path.iterdir()) == []


def test_an_import_that_cannot_fit_is_refused_before_copying(camp, field_copy, monkeypatch):
    import common.files

    before = snapshot(camp)
    monkeypatch.setattr(common.files, "free_bytes", lambda path: 1000)
    r = main(["add-epoch", str(camp), "--date", "2026-03-02", "--coarse", str(field_copy / "v0" / "coarse.laz")])
    assert r == 1 and snapshot(camp) == before


# ---------------------------------------------------------------------------------------------- thin inputs
def test_a_target_no_station_can_reach_is_a_warning_at_init_plan_and_status(field_copy, tmp_path, capsys):
    layout = field_copy / "layout.csv"
    text = layout.read_text().rstrip("\n").splitlines()
    far = text[-1].split(",")
    far[0], far[2] = "M9", str(float(far[2]) + 10000.0)
    layout.write_text("\n".join(text + [",".join(far)]) + "\n")
    camp = tmp_path / "far"
    assert main(["init", str(camp), "--name", "Far", "--layout", str(layout)]) == 0
    out = capsys.readouterr().out
    assert "warning: layout target M9 is 9,9" in out and "beyond the Riegl VZ-1000's range of 1,400 m" in out
    assert main(["add-epoch", str(camp), "--date", "2026-03-02", "--coarse", str(field_copy / "v0" / "coarse.laz")]) == 0
    assert main(["plan", str(camp), "--epoch", "2026-03-02", "--out", str(tmp_path / "plan.json")]) == 0
    assert "warning: layout target M9" in capsys.readouterr().out
    assert main(["status", str(camp)]) == 0
    assert "warning: layout target M9" in capsys.readouterr().out
    assert main(["status", str(camp), "--json"]) == 0
    assert any("M9" in w for w in json.loads(capsys.readouterr().out)["warnings"])


def test_epoch_dates_far_from_the_others_need_allow_date(camp, field_copy, capsys):
    coarse = [str(field_copy / f"v{k}" / "coarse.laz") for k in range(3)]
    assert main(["add-epoch", str(camp), "--date", "2026-03-02", "--coarse", coarse[0]]) == 0
    before = snapshot(camp)
    capsys.readouterr()
    for date in ("1900-01-01", "2200-06-01"):
        assert main(["add-epoch", str(camp), "--date", date, "--coarse", coarse[1]]) == 1
        err = capsys.readouterr().err
        assert "years" in err and "--allow-date" in err and len(err.strip().splitlines()) == 1
    assert snapshot(camp) == before
    assert main(["add-epoch", str(camp), "--date", "2027-06-01", "--coarse", coarse[1]]) == 0  # within 3 years
    assert main(["add-epoch", str(camp), "--date", "1990-01-01", "--coarse", coarse[2], "--allow-date"]) == 0


def test_an_earlier_epoch_never_becomes_the_baseline_silently(processed_copy, field_copy, tmp_path, capsys):
    with Campaign.open(processed_copy) as c:
        labels = [e.label for e in c.epochs()]
        c.set_setting("baseline", None)  # as after measuring without 'process' (the GUI's check)
    earlier = tmp_path / "earlier.laz"  # the first visit's scan under another checksum (a valid LAS file)
    data = bytearray((field_copy / "v0" / "coarse.laz").read_bytes())
    data[90] ^= 1  # the header's file creation day
    earlier.write_bytes(bytes(data))
    assert main(["add-epoch", str(processed_copy), "--date", "2026-02-23", "--coarse", str(earlier)]) == 0
    out = capsys.readouterr().out
    assert f"dated before the baseline {labels[0]}" in out
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.settings()["baseline"] == labels[0]


def test_an_imported_scan_is_hashed_once(camp, field_copy, monkeypatch):
    """add-epoch hashes each file once: the duplicate check's checksum names the copy, which hashes nothing."""
    import hashlib
    import types

    import projects.store.campaign as campaign
    import projects.store.imports as imports

    hashed: list[str] = []

    def counted(path, *args, **kwargs):
        hashed.append(str(path))
        return sha256_of(path, *args, **kwargs)

    def copy_hash(*args):  # with bytes: the first 64 KiB the journal records (header_facts), not the file
        if not args:
            hashed.append("copy")
        return hashlib.sha256(*args)

    coarse = field_copy / "v0" / "coarse.laz"
    monkeypatch.setattr(campaign, "sha256_of", counted)
    monkeypatch.setattr(imports, "sha256_of", counted)
    monkeypatch.setattr(imports, "hashlib", types.SimpleNamespace(sha256=copy_hash))
    with Campaign.open(camp) as c:
        c.add_epoch("2026-03-02", "2026-03-02T09:00:00+00:00", coarse)
        stored = c.files("2026-03-02")[0]
    assert hashed == [str(coarse)]
    assert stored.sha256 == sha256_of(coarse)
    assert sha256_of(camp / stored.stored_path) == stored.sha256

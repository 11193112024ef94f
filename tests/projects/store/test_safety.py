"""Crash safety, locking and versioning of the campaign store."""
from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.cli.main import main
from projects.store import journal
from projects.store.campaign import DB_NAME, Campaign
from projects.store.errors import CampaignError, CampaignLockedError
from projects.store.imports import BY_VISIT

CLI = [sys.executable, "-c", "import sys; from app.cli.main import main; sys.exit(main())"]


@pytest.fixture
def campaign(field_copy, tmp_path, capsys):
    camp = tmp_path / "camp"
    assert main(["init", str(camp), "--name", "Safety", "--layout", str(field_copy / "layout.csv")]) == 0
    capsys.readouterr()
    return camp


def run_and_kill(argv, delay):
    proc = subprocess.Popen(CLI + argv, cwd=Path(__file__).resolve().parents[3], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    time.sleep(delay)
    if proc.poll() is None:
        proc.send_signal(signal.SIGKILL)
    proc.wait()
    return proc.returncode


@pytest.mark.slow
@pytest.mark.parametrize("delay", [0.3, 1.0, 2.0, 3.5])
def test_kill_9_during_import_and_processing_leaves_a_valid_campaign(campaign, field_copy, delay, capsys):
    coarse = str(field_copy / "v0" / "coarse.laz")
    run_and_kill(["add-epoch", str(campaign), "--date", "2026-03-02", "--coarse", coarse], delay)
    with Campaign.open(campaign) as c:
        assert c.integrity_check() == "ok"
        epochs = c.epochs()
        stored = {f"scans/{p.name}" for p in (campaign / "scans").iterdir() if p.name != BY_VISIT}
        listed = {f.stored_path for e in epochs for f in c.files(e.label)}
        # no half file (temporary copies are removed); a complete copy the database did not get to list is
        # kept, and the journal knows it (killed between the rename and the commit: 'repair' registers it)
        assert listed <= stored and stored - listed <= set(journal.latest_by_path(campaign))
    if not epochs:  # killed before the commit: the same command completes it
        assert main(["add-epoch", str(campaign), "--date", "2026-03-02", "--coarse", coarse]) == 0
    run_and_kill(["process", str(campaign)], delay)
    with Campaign.open(campaign) as c:
        assert c.integrity_check() == "ok"
    assert main(["process", str(campaign)]) == 0
    with Campaign.open(campaign) as c:
        assert c.result("2026-03-02").stage == "planned"
        assert c.integrity_check() == "ok"


def test_second_writer_is_refused_with_a_clear_message(campaign):
    with Campaign.open(campaign):
        with pytest.raises(CampaignLockedError, match="in use by BridgeSurvey process"):
            Campaign.open(campaign)
        res = subprocess.run(CLI + ["reflector", "retire", str(campaign), "R1", "--date", "2026-01-01"],
                             cwd=Path(__file__).resolve().parents[3], capture_output=True, text=True)
        assert res.returncode == 1 and "in use by" in res.stderr
    with Campaign.open(campaign, writable=False):
        with Campaign.open(campaign, writable=False):  # readers share
            pass


def test_newer_campaign_is_refused_and_garbage_is_not_a_campaign(campaign, tmp_path):
    conn = sqlite3.connect(campaign / DB_NAME)
    with conn:
        conn.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    conn.close()
    with pytest.raises(CampaignError, match="newer BridgeSurvey"):
        Campaign.open(campaign)
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / DB_NAME).write_bytes(b"not a database at all" * 100)
    with pytest.raises(CampaignError, match="not a readable campaign database"):
        Campaign.open(junk)


def test_older_campaign_is_migrated(campaign, monkeypatch):
    from projects.store import schema

    nxt = schema.SCHEMA_VERSION + 1
    monkeypatch.setattr(schema, "SCHEMA_VERSION", nxt)
    monkeypatch.setitem(schema.MIGRATIONS, nxt, "ALTER TABLE epochs ADD COLUMN weather TEXT;")
    with Campaign.open(campaign, writable=False) as c:  # readers upgrade too (briefly exclusive)
        assert schema.version_of(c.conn) == nxt
        assert "weather" in [r[1] for r in c.conn.execute("PRAGMA table_info(epochs)")]


def test_version_1_campaign_migrates_to_current_with_its_data(tmp_path):
    """A campaign written by the first release (schema 1) opens, upgrades and keeps every row."""
    import sqlite3

    from projects.store import schema

    folder = tmp_path / "old"
    (folder / "scans").mkdir(parents=True)
    conn = sqlite3.connect(folder / DB_NAME)
    with conn:
        conn.executescript(schema.SCHEMA_V1)
        conn.execute("INSERT INTO meta VALUES ('schema_version', '1')")
        conn.executemany("INSERT INTO meta VALUES (?, ?)", [("name", "Old bridge"), ("span_m", "40.0"),
                                                            ("settings", "{}"), ("created", "2025-01-01T00:00:00")])
        conn.execute("INSERT INTO reflectors(id, grp, x, y, z, diameter_m) VALUES ('M1', 'measurement', 1, 2, 3, 0.05)")
        conn.execute("INSERT INTO epochs VALUES ('e1', '2025-01-06T09:00:00', '', '2025-01-06T10:00:00')")
        conn.execute("INSERT INTO centroids VALUES ('e1', 'M1', 1, 1.0, 2.0, 3.0, '[[0,0,0],[0,0,0],[0,0,0]]', "
                     "900, 0.5, 0.9, 0.005, '[]')")
    conn.close()
    with Campaign.open(folder) as c:
        assert schema.version_of(c.conn) == schema.SCHEMA_VERSION
        assert c.name == "Old bridge" and [e.label for e in c.epochs()] == ["e1"]
        t = c.centroids("e1")["M1"]
        assert t.n_points == 900 and t.n_window == -1  # not recorded before schema 2
        assert c.map_preview("e1") is None


def test_imported_files_are_read_only_copies(campaign, field_copy):
    src = field_copy / "v1" / "coarse.laz"
    before = src.read_bytes()
    assert main(["add-epoch", str(campaign), "--date", "2026-03-09", "--coarse", str(src)]) == 0
    assert src.read_bytes() == before
    stored = next(p for p in (campaign / "scans").iterdir() if p.name != BY_VISIT)
    assert stored.read_bytes() == before and not os.access(stored, os.W_OK) or os.geteuid() == 0
    assert oct(stored.stat().st_mode & 0o777) == "0o444"

"""Fault injection, round 3 (issue 42): every row of the issue's table ends in one line, nothing damaged is served.

A changed scan, a changed limit or epoch date, a damaged displacement set, a restored database beside a
later run's write-ahead log, dropped tables, read-only files and folders, a folder moved mid-run, a date
no time axis holds, damaged reflectors and scanner profiles, and temporary files a kill left.
"""
from __future__ import annotations

import os
import pwd
import shutil
import sqlite3
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from common.errors import SurveyError
from common.files import atomic_output
from projects.store import digests, schema, wal
from projects.store.campaign import DB_NAME, Campaign
from tests.projects.store.test_faults import one_line, run, stored_scans, tables, variant
from tests.projects.store.test_integrity import back_to_version_11

LAST = "2026-03-16"


def sql(folder: Path, *statements: str) -> None:
    """Change the database behind the store's back, as a flipped byte or another tool would."""
    conn = sqlite3.connect(folder / DB_NAME)
    with conn:
        for s in statements:
            conn.execute(s)
    conn.close()


def version(folder: Path) -> str:
    conn = sqlite3.connect(folder / DB_NAME)
    try:
        return conn.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()[0]
    finally:
        conn.close()


# ---------------------------------------------------------------------------------------------- scans checked
def test_a_changed_scan_stops_its_visit_in_process(processed_copy, capsys):
    _, fine = stored_scans(processed_copy, LAST)
    data = bytearray(fine.read_bytes())
    (z,) = struct.unpack_from("<d", data, 147)  # the LAS header's Z scale factor
    struct.pack_into("<d", data, 147, z * 1.0002)
    os.chmod(fine, 0o644)
    fine.write_bytes(bytes(data))
    assert run(capsys, "settings", processed_copy, "min_points", "900")[0] == 0  # every visit plans again
    rc, out, err = run(capsys, "process", processed_copy)
    assert rc == 1
    assert "changed since its import" in err and fine.name in err and "restore it from a backup" in err
    assert "Traceback" not in err
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and f"CHANGED scans/{fine.name}" in out


# ---------------------------------------------------------------------------------------------- input rows
def test_a_changed_limit_is_named_by_every_command_and_verify_and_repair_sets_it_again(processed_copy, capsys):
    sql(processed_copy, "UPDATE limits SET alarm_mm = alarm_mm * 10")
    for argv in (("status", processed_copy), ("displacements", processed_copy),
                 ("report", processed_copy, "--out", processed_copy.parent / "r.pdf")):
        rc, _, err = run(capsys, *argv)
        assert rc == 1, argv
        one_line(err, "the limit of every measurement target (*) is damaged", "repair")
    assert not (processed_copy.parent / "r.pdf").exists()
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and "DAMAGED the limit of every measurement target" in out
    rc, out, _ = run(capsys, "repair", processed_copy)
    assert rc == 0 and "set again from the campaign's log (kr-rail:0-200)" in out
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.limit_for("M1").alarm_mm == pytest.approx(40.0 / 1.9)  # 40 m / 1900, in mm
        assert c.damaged_inputs() == []


def test_a_changed_epoch_date_is_named_and_put_back_from_the_journal(processed_copy, capsys):
    sql(processed_copy, f"UPDATE epochs SET datetime = '2026-03-19T08:30:00+00:00' WHERE label = '{LAST}'")
    for argv in (("status", processed_copy), ("displacements", processed_copy), ("process", processed_copy)):
        rc, _, err = run(capsys, *argv)
        assert rc == 1, argv
        one_line(err, f"epoch {LAST} is damaged", "journal of imports")
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and f"DAMAGED epoch {LAST}" in out
    assert run(capsys, "repair", processed_copy)[0] == 0
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.epoch(LAST).datetime == "2026-03-16T08:30:00+00:00"
    assert run(capsys, "verify", processed_copy)[0] == 0


@pytest.mark.parametrize("statement, words", [
    ("UPDATE reflectors SET x = x + 0.01 WHERE id = (SELECT min(id) FROM reflectors)", "reflector"),
    ("UPDATE meta SET value = replace(value, '122000', '122001') WHERE key = 'scanner_profile'",
     "the campaign's scanner profile is damaged"),
    ("UPDATE meta SET value = '{\"min_points\": 500}' WHERE key = 'settings'", "the campaign's settings record"),
])
def test_a_damaged_reflector_scanner_or_setting_is_named_never_used(processed_copy, capsys, statement, words):
    sql(processed_copy, statement)
    rc, _, err = run(capsys, "process", processed_copy)
    assert rc == 1
    one_line(err, words, "restore campaign.sqlite from a backup")
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and "DAMAGED" in out
    rc, out, _ = run(capsys, "repair", processed_copy)
    assert rc == 3 and "left:" in out and words in out


def test_a_damaged_field_model_is_fitted_again(processed_copy, capsys):
    sql(processed_copy, "UPDATE field_models SET created = 'x'")
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and "DAMAGED the field model" in out
    assert run(capsys, "process", processed_copy)[0] == 0
    assert run(capsys, "verify", processed_copy)[0] == 0


def test_the_input_digest_migration_seals_an_older_campaign(processed_copy):
    conn = sqlite3.connect(processed_copy / DB_NAME)
    back_to_version_11(conn)
    conn.commit()
    conn.close()
    with Campaign.open(processed_copy) as c:
        assert schema.version_of(c.conn) == schema.SCHEMA_VERSION == 13
        assert c.damaged_inputs() == [] and c.limits() and len(c.epochs()) == 3
        assert all(r["digest"] for r in c.conn.execute("SELECT digest FROM limits"))


def test_a_damaged_displacement_set_is_named_by_every_reader(processed_copy, capsys):
    sql(processed_copy, f"UPDATE displacements SET displacement_m = displacement_m + 0.0005 WHERE epoch = '{LAST}'")
    rc, out, err = run(capsys, "displacements", processed_copy, "--format", "csv")
    assert rc == 0 and LAST not in out
    one_line(err, f"the displacements of epoch {LAST} are damaged", "left out", "process")
    rc, _, err = run(capsys, "export", processed_copy, "--out", processed_copy.parent / "a.csv")
    assert rc == 0
    one_line(err, f"epoch {LAST} are damaged")
    from projects.outputs.report.content import gather

    with Campaign.open(processed_copy, writable=False) as c:
        sections = {s.label: s for s in gather(c, with_previews=False).epochs}
    assert f"epoch {LAST} are damaged" in sections[LAST].damaged and not sections["2026-03-02"].damaged


# ---------------------------------------------------------------------------------------------- restore
def test_a_restored_database_never_reads_a_later_runs_log(processed_copy, tmp_path, capsys):
    db = processed_copy / DB_NAME
    backup = tmp_path / "backup.sqlite"
    shutil.copy2(db, backup)
    assert run(capsys, "settings", processed_copy, "min_points", "900")[0] == 0  # the file moves on
    # a writer killed after its commits: they are in the log only
    subprocess.run([sys.executable, "-c", "import os\nfrom projects.store.campaign import Campaign\n"
                    "c = Campaign.open(os.environ['CAMP'])\nc.set_limit('*', 'kr-rail:200-270')\nos._exit(0)"],
                   env={**os.environ, "CAMP": str(processed_copy)}, check=True, cwd=Path(__file__).parents[3])
    assert wal.wal_salts(db) is not None
    shutil.copy2(backup, db)  # the older database restored, the log left beside it
    for argv in (("status", processed_copy), ("displacements", processed_copy), ("verify", processed_copy),
                 ("process", processed_copy), ("repair", processed_copy)):
        rc, out, err = run(capsys, *argv)
        assert rc == 1 and not out, argv
        one_line(err, "campaign.sqlite-wal beside it belongs to another version", "move campaign.sqlite-wal and "
                 "campaign.sqlite-shm out of")
    for name in (DB_NAME + "-wal", DB_NAME + "-shm"):
        (processed_copy / name).unlink(missing_ok=True)
    rc, out, _ = run(capsys, "status", processed_copy)
    assert rc == 0
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.limit_for("M1").rule == "kr-rail:0-200" and "min_points" not in c.settings()


def test_a_log_killed_in_its_checkpoint_or_without_a_record_is_read(processed_copy, capsys):
    db = processed_copy / DB_NAME
    subprocess.run([sys.executable, "-c", "import os\nfrom projects.store.campaign import Campaign\n"
                    "c = Campaign.open(os.environ['CAMP'])\nc.set_limit('*', 'kr-rail:200-270')\nos._exit(0)"],
                   env={**os.environ, "CAMP": str(processed_copy)}, check=True, cwd=Path(__file__).parents[3])
    salts = wal.wal_salts(db)
    assert salts is not None
    # killed after the database file was written by the checkpoint, before the record was: read
    wal.owner_path(db).write_text(f'{{"state": "checkpointing", "wal": {list(salts)}, "db": [0, 0]}}')
    wal.check(db)
    wal.owner_path(db).unlink()  # a campaign of an older BridgeSurvey: no record, read as before
    wal.check(db)
    rc, out, _ = run(capsys, "status", processed_copy)
    assert rc == 0
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.limit_for("M1").rule == "kr-rail:200-270"


# ---------------------------------------------------------------------------------------------- lost tables
@pytest.mark.parametrize("table", ["centroids", "files", "epochs", "limits", "displacement_sets", "meta"])
def test_a_dropped_table_is_one_line_and_repair_makes_it_again_or_says_it_cannot(processed, processed_copy, table,
                                                                                 capsys):
    sql(processed_copy, f"DROP TABLE {table}")
    for argv in (("status", processed_copy), ("verify", processed_copy), ("process", processed_copy),
                 ("displacements", processed_copy), ("report", processed_copy, "--out", processed_copy / "r.pdf")):
        rc, _, err = run(capsys, *argv)
        assert rc == 1, argv
        one_line(err, f"lacks table {table}", "restore campaign.sqlite from a backup")
    rc, out, err = run(capsys, "repair", processed_copy)
    if table == "meta":
        assert rc == 1
        one_line(err, "lacks table meta", "restore campaign.sqlite from a backup")
        return
    assert rc == 0 and f"table {table} made again" in out, out + err
    assert version(processed_copy) == str(schema.SCHEMA_VERSION)
    assert run(capsys, "process", processed_copy)[0] == 0
    assert run(capsys, "verify", processed_copy)[0] == 0
    got, want = tables(processed_copy), tables(processed)
    assert [r[:2] for r in got] == [r[:2] for r in want]
    assert max(abs(a[2] - b[2]) for a, b in zip(got, want, strict=True) if a[2] is not None) < 1e-4


@pytest.mark.parametrize("table", ["reflectors", "events"])
def test_repair_never_lowers_the_schema_version(processed_copy, table, capsys):
    sql(processed_copy, f"DROP TABLE {table}")
    before = version(processed_copy)
    rc, _, err = run(capsys, "repair", processed_copy)
    assert rc == 1
    one_line(err, f"lacks {table}", "nothing was changed", "restore campaign.sqlite from a backup")
    assert version(processed_copy) == before == str(schema.SCHEMA_VERSION)


def test_repair_of_an_older_campaign_with_a_lost_table_keeps_its_version(processed_copy, capsys):
    sql(processed_copy, "UPDATE meta SET value = '11' WHERE key = 'schema_version'", "DROP TABLE comparisons")
    rc, _, err = run(capsys, "repair", processed_copy)
    assert rc == 1
    one_line(err, "never lowers the version")
    assert version(processed_copy) == "11"


# ---------------------------------------------------------------------------------------------- read-only
def _as_nobody(*argv) -> subprocess.CompletedProcess:
    """A command run as an unprivileged user (root writes read-only files), from this worktree."""
    if os.geteuid() != 0:
        return subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, argv)], capture_output=True, text=True,
                              cwd=Path(__file__).parents[3])
    if shutil.which("setpriv") is None:
        pytest.skip("no setpriv to run a command as another user")
    nobody = pwd.getpwnam("nobody")
    return subprocess.run(["setpriv", f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups",
                           sys.executable, "-m", "app.cli.main", *map(str, argv)], capture_output=True, text=True,
                          cwd=Path(__file__).parents[3], env={**os.environ, "HOME": "/tmp"})


@pytest.fixture
def shared_copy(processed_copy):
    """The processed campaign in a folder every user may read and write (its parents opened to them)."""
    for p in [processed_copy, *processed_copy.parents]:
        if p == Path("/"):
            break
        p.chmod(p.stat().st_mode | 0o755)
    _open_to_all(processed_copy)
    return processed_copy


def _open_to_all(folder: Path) -> None:
    for p in [folder, *folder.rglob("*")]:
        p.chmod(0o777 if p.is_dir() else 0o666)


def test_a_read_only_database_in_a_writable_folder_is_read_and_writers_get_one_line(shared_copy, field):
    (shared_copy / DB_NAME).chmod(0o444)
    r = _as_nobody("status", shared_copy)
    assert r.returncode == 0, r.stderr
    for argv in (("process", shared_copy), ("settings", shared_copy, "min_points", "900")):
        r = _as_nobody(*argv)
        assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
        one_line(r.stderr, "read-only", "nothing was changed")


def test_a_read_only_scans_folder_refuses_an_import_in_one_line(shared_copy, tmp_path):
    coarse, _ = stored_scans(shared_copy, LAST)
    new = variant(coarse, tmp_path / "new" / "c.laz")
    for p in (new, new.parent, tmp_path):
        p.chmod(0o755 if p.is_dir() else 0o644)
    _open_to_all(shared_copy)  # what reading it as root left (the lock file) too
    (shared_copy / "scans").chmod(0o555)
    r = _as_nobody("add-epoch", shared_copy, "--date", "2026-03-23", "--coarse", new)
    assert r.returncode == 1, r.stderr
    one_line(r.stderr, "scans: this folder is read-only", "nothing was changed")
    with Campaign.open(shared_copy, writable=False) as c:
        assert len(c.epochs()) == 3


# ---------------------------------------------------------------------------------------------- moved, dates
def test_a_folder_moved_while_process_runs_is_one_line_and_the_next_run_is_fine(processed_copy, tmp_path, capsys):
    from projects.processing.stages import process

    assert run(capsys, "settings", processed_copy, "min_points", "900")[0] == 0
    moved = tmp_path / "moved"

    def move_once(fraction, message=""):
        if not moved.exists():
            processed_copy.rename(moved)

    with Campaign.open(processed_copy) as c, pytest.raises(SurveyError, match="no longer there") as err:
        process(c, progress=move_once)
    assert "\n" not in str(err.value)
    rc, _, _ = run(capsys, "process", moved)
    assert rc == 0
    assert run(capsys, "verify", moved)[0] == 0


def test_a_date_no_time_axis_holds_is_refused_and_an_old_one_is_one_line_in_report(processed_copy, tmp_path, capsys):
    coarse, _ = stored_scans(processed_copy, LAST)
    new = variant(coarse, tmp_path / "c.laz")
    rc, _, err = run(capsys, "add-epoch", processed_copy, "--date", "0001-01-01", "--coarse", new, "--allow-date")
    assert rc == 1
    one_line(err, "0001-01-01 is outside the years BridgeSurvey computes with")
    # a campaign that holds such an epoch already (an older BridgeSurvey let it in)
    when = "0001-01-01T00:00:00+00:00"
    sql(processed_copy, f"UPDATE epochs SET datetime = '{when}' WHERE label = '2026-03-02'",
        f"UPDATE epochs SET digest = '{digests.row_digest('epochs', ('2026-03-02', when, 'visit 1', 'x'))}' "
        "WHERE label = '2026-03-02'", "UPDATE epochs SET created = 'x' WHERE label = '2026-03-02'")
    rc, _, err = run(capsys, "report", processed_copy, "--out", tmp_path / "r.pdf")
    assert rc == 1
    one_line(err, "epoch 2026-03-02 is dated 0001-01-01", "no report was written")
    assert not (tmp_path / "r.pdf").exists()
    rc, _, err = run(capsys, "process", processed_copy)
    assert "Traceback" not in err


# ---------------------------------------------------------------------------------------------- temporary files
def test_temporary_files_a_kill_left_are_named_then_removed(processed_copy, tmp_path, capsys):
    left = processed_copy / ".bias.part.json"
    left.write_text("{")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    (out_dir / ".r.part.pdf").write_bytes(b"%PDF")
    (out_dir / ".analysis.part.json").write_text("{")
    rc, _, err = run(capsys, "status", processed_copy)
    assert rc == 0 and ".bias.part.json" in err
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3 and "TEMPORARY .bias.part.json" in out
    assert left.exists()  # readers never delete
    assert run(capsys, "settings", processed_copy, "min_points", "900")[0] == 0  # any writer
    assert not left.exists()
    assert run(capsys, "displacements", processed_copy, "--out", out_dir / "d.csv")[0] == 0  # any output there
    assert sorted(p.name for p in out_dir.iterdir()) == ["d.csv"]


def test_a_writer_at_work_keeps_its_temporary_file(tmp_path):
    with atomic_output(tmp_path / "a.json") as tmp:
        tmp.write_text("{}")
        with atomic_output(tmp_path / "b.json") as other:  # another output written beside it meanwhile
            other.write_text("{}")
            assert tmp.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.json"]


def test_a_dropped_table_in_python_is_a_campaign_error(processed_copy):
    sql(processed_copy, "DROP TABLE limits")
    with pytest.raises(SurveyError, match="lacks table limits"):
        Campaign.open(processed_copy, writable=False)

"""Fault injection (issue 29): what an unlucky user meets ends with nothing lost, one line and the right word.

A restored older database over a newer folder, a full disk (patched writers at every write point of
add-epoch, process, report and export, and a real small tmpfs where it can be mounted), flipped bytes
in stored results, damaged schema versions, a stale lock, and kill -9 at random moments of every
writing command.
"""
from __future__ import annotations

import builtins
import contextlib
import errno
import io
import math
import os
import random
import re
import shutil
import signal
import sqlite3
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from projects.store import campaign as campaign_module
from projects.store import digests, imports, journal, schema
from projects.store.campaign import DB_NAME, Campaign
from tests.projects.campaign_helpers import snapshot

ROOT = Path(__file__).resolve().parents[3]
CLI = [sys.executable, "-c", "import sys; from app.cli.main import main; sys.exit(main())"]
FULL = "no space left on the device holding"


def run(capsys, *argv) -> tuple[int, str, str]:
    """A command run here (one interpreter: fast), with what it printed."""
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


PROGRESS = re.compile(r"^[^:]+: +\d+%")  # the progress lines of long commands (stderr is not a terminal here)


def one_line(err: str, *words: str) -> None:
    """The error output is one line (progress aside), no traceback, with these words."""
    lines = [ln for ln in err.strip().splitlines() if not PROGRESS.match(ln)]
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], lines[0]


def variant(scan: Path, dst: Path, k: int = 1) -> Path:
    """The same LAS scan under another checksum (its header's file-creation day changed): a new visit's file."""
    data = bytearray(scan.read_bytes())
    data[90] ^= k
    dst.parent.mkdir(parents=True, exist_ok=True)
    dst.write_bytes(bytes(data))
    return dst


def tables(folder: Path):
    with Campaign.open(folder, writable=False) as c:
        return [(d.epoch, d.reflector, d.displacement_m, d.sigma_m, d.flags) for d in c.displacements()]


def folder_files(folder: Path) -> dict[str, bytes]:
    return {rel: (folder / rel).read_bytes() for rel in imports.folder_files(folder)}


def stored_scans(folder: Path, label: str) -> tuple[Path, Path]:
    with Campaign.open(folder, writable=False) as c:
        return c.path_of(c.files(label, "coarse")[0]), c.path_of(c.files(label, "fine")[0])


def make_stale(folder: Path) -> str:
    """Forget the last epoch's centroids and displacements (its plan stays): 'process' measures it again."""
    with Campaign.open(folder) as c:
        label = c.epochs()[-1].label
        with c.transaction() as conn:
            conn.execute("DELETE FROM displacement_sets WHERE epoch = ?", (label,))
            conn.execute("DELETE FROM centroids WHERE epoch = ?", (label,))
            conn.execute("DELETE FROM epoch_results WHERE epoch = ?", (label,))
    return label


def camera_csv(path: Path) -> Path:
    from vision.simulate.series import simulate_series, write_series_csv

    t0, t1 = (np.datetime64(d, "ns").astype(np.int64) for d in ("2026-02-28T00:00", "2026-03-25T00:00"))
    t, v = simulate_series(t0, t1, lambda t: np.zeros(len(t)), noise_mm=0.1, zero_offset_mm=3.0)
    return write_series_csv(path, t, v)


def temperature_csv(path: Path) -> Path:
    rows = ["time,temperature_C"] + [f"2026-03-{d:02d}T{h:02d}:00,{8 + 5 * np.sin(h / 24 * 6.28):.2f}"
                                     for d in range(1, 26) for h in range(24)]
    path.write_text("\n".join(rows) + "\n")
    return path


# ------------------------------------------------------------------------------------------ restore
def test_restoring_an_older_database_keeps_every_file_and_repair_registers_them(processed_copy, tmp_path, capsys):
    camp = processed_copy
    backup = tmp_path / "yesterday.sqlite"
    shutil.copy(camp / DB_NAME, backup)
    coarse, fine = stored_scans(camp, "2026-03-02")
    visit = tmp_path / "visit4"
    rc, _, err = run(capsys, "add-epoch", camp, "--date", "2026-03-23T09:00", "--coarse", variant(coarse, visit / "c.laz"),
                     "--fine", variant(fine, visit / "f.laz"), "--scanner", "Riegl VZ-1000")
    assert rc == 0, err
    assert run(capsys, "camera", "import", camp, camera_csv(tmp_path / "midspan.csv"))[0] == 0
    assert run(capsys, "env", "import", camp, temperature_csv(tmp_path / "air.csv"), "--kind", "temperature")[0] == 0
    assert run(capsys, "process", camp)[0] in (0, 3)
    today, files = tables(camp), folder_files(camp)
    assert len(files) == 6 + 2 + 2

    shutil.copy(backup, camp / DB_NAME)  # yesterday's backup over today's folder
    for extra in ("-wal", "-shm"):
        with contextlib.suppress(FileNotFoundError):
            (camp / (DB_NAME + extra)).unlink()
    assert run(capsys, "process", camp)[0] in (0, 3)
    assert folder_files(camp) == files  # nothing imported was deleted
    rc, out, _ = run(capsys, "status", camp)
    assert rc == 0 and "4 file(s) in the campaign folder that the database does not list" in out
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 3 and out.count("UNLISTED ") == 4 and "the journal has it as the coarse scan of epoch 2026-03-23" in out
    rc, out, _ = run(capsys, "repair", camp)
    assert rc == 0, out
    assert out.count("registered again as the") == 2 and "the epoch was created again" in out
    assert "camera series 'midspan' read again" in out and "environment series 'air' read again" in out
    assert "its own scanner (Riegl VZ-1000) set again" in out and "nothing was deleted" in out
    assert run(capsys, "process", camp)[0] in (0, 3)
    rc, out, _ = run(capsys, "verify", camp)
    assert rc == 0, out
    assert tables(camp) == today and folder_files(camp) == files
    with Campaign.open(camp, writable=False) as c:
        (cam,) = c.series.records("camera_series")
        assert cam.name == "midspan" and cam.original_path == str((tmp_path / "midspan.csv").resolve())
        assert "2026-03-23" in c.settings()["epoch_scanners"]


def test_repair_leaves_a_file_it_cannot_vouch_for(processed_copy, tmp_path, capsys):
    scans = processed_copy / "scans"
    unknown = scans / "0123456789abcdef_someone-elses.laz"
    unknown.write_bytes(b"not in the journal")
    with Campaign.open(processed_copy, writable=False) as c:
        label = c.epochs()[-1].label
        rel = c.files(label, "fine")[0].stored_path
    with Campaign.open(processed_copy) as c:  # the database forgets a file, and the file is then damaged
        with c.transaction() as conn:
            conn.execute("DELETE FROM files WHERE stored_path = ?", (rel,))
    damaged = processed_copy / rel
    damaged.chmod(0o644)
    data = bytearray(damaged.read_bytes())
    data[-10] ^= 0xFF
    damaged.write_bytes(bytes(data))
    rc, out, _ = run(capsys, "repair", processed_copy)
    assert rc == 3 and "0 repair(s), 2 left" in out
    assert "cannot tell what it was imported as" in out and "checksum no longer matches" in out
    assert unknown.exists() and damaged.exists()


# ------------------------------------------------------------------------------------------ a full disk
def _enospc(*_a, **_k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@contextlib.contextmanager
def sql_full(monkeypatch, table: str, action: str):
    """Every campaign opened for writing fails ``action`` on ``table`` as SQLite does on a full disk."""
    real = campaign_module.open_database

    def opened(db, *, writable):
        conn = real(db, writable=writable)
        if writable:
            conn.execute(f"CREATE TEMP TRIGGER disk_full BEFORE {action} ON main.{table} BEGIN "
                         "SELECT RAISE(FAIL, 'database or disk is full'); END")
        return conn
    with monkeypatch.context() as m:
        m.setattr(campaign_module, "open_database", opened)
        yield


@contextlib.contextmanager
def file_full(monkeypatch, match):
    """Writing a file whose name ``match`` accepts fails with ENOSPC (after the first bytes, as a disk fills)."""
    real_open = builtins.open

    class Filling(io.FileIO):
        def write(self, b):
            super().write(bytes(b)[:10])
            _enospc()

    def fake_open(file, mode="r", *args, **kwargs):
        if isinstance(file, (str, os.PathLike)) and any(c in mode for c in "wax") and match(Path(file).name):
            raw = Filling(os.fspath(file), mode.replace("b", "").replace("t", "").replace("+", "") or "w")
            return raw if "b" in mode else io.TextIOWrapper(raw, encoding=kwargs.get("encoding") or "utf-8")
        return real_open(file, mode, *args, **kwargs)
    with monkeypatch.context() as m:
        m.setattr(builtins, "open", fake_open)
        m.setattr(io, "open", fake_open)
        yield


def _partial_output(name: str) -> bool:  # common.files.atomic_output's temporary names
    return name.startswith(".") and ".part" in name


ADD_EPOCH_POINTS = [
    ("free space checked first", lambda m: m.setattr("common.files.free_bytes", lambda p: 4096)),
    ("copying the scan", lambda m: file_full(m, lambda n: n.startswith(".import-"))),
    ("writing the journal", lambda m: m.setattr(journal, "append", _enospc)),
    ("the epoch row", lambda m: sql_full(m, "epochs", "INSERT")),
    ("the file rows", lambda m: sql_full(m, "files", "INSERT")),
    ("the log", lambda m: sql_full(m, "log", "INSERT")),
]


@pytest.mark.parametrize("point", [p[0] for p in ADD_EPOCH_POINTS])
def test_a_full_disk_at_each_write_point_of_add_epoch_is_one_line_and_changes_nothing(processed_copy, tmp_path,
                                                                                      capsys, monkeypatch, point):
    coarse, fine = stored_scans(processed_copy, "2026-03-02")
    args = ("add-epoch", processed_copy, "--date", "2026-03-23", "--coarse", variant(coarse, tmp_path / "c.laz"),
            "--fine", variant(fine, tmp_path / "f.laz"))
    before = snapshot(processed_copy)
    inject = dict(ADD_EPOCH_POINTS)[point]
    with monkeypatch.context() as m:
        ctx = inject(m)
        with ctx if ctx is not None else contextlib.nullcontext():
            rc, _, err = run(capsys, *args)
    assert rc == 1
    one_line(err, FULL, "run the command again")
    assert snapshot(processed_copy) == before  # not a row, not a file, not a journal line
    rc, _, err = run(capsys, *args)  # space freed: the same command completes
    assert rc == 0, err


@pytest.fixture
def cached_stage1(monkeypatch):
    """Stage 1 computed once per job and reused: the disk-full runs test the writes, not the computing."""
    from projects.processing import stages

    cache: dict = {}
    real = stages.run_stage1

    def run_stage1(job, **kw):
        key = (job.folder, job.label, job.plan_hash, job.measure_hash)
        if key not in cache:
            cache[key] = real(job, **kw)
        return cache[key]
    monkeypatch.setattr(stages, "run_stage1", run_stage1)


PROCESS_POINTS = [("centroids", "INSERT"), ("epoch_results", "INSERT"), ("epoch_results", "UPDATE"),
                  ("displacement_sets", "INSERT"), ("displacements", "INSERT"), ("reference_checks", "INSERT"),
                  ("log", "INSERT")]


@pytest.mark.parametrize("table, action", PROCESS_POINTS)
def test_a_full_disk_at_each_write_point_of_process_is_one_line_and_leaves_a_sound_campaign(
        processed, processed_copy, capsys, monkeypatch, cached_stage1, table, action):
    reference = tables(processed)
    label = make_stale(processed_copy)
    with sql_full(monkeypatch, table, action):
        rc, _, err = run(capsys, "process", processed_copy)
    assert rc == 1
    one_line(err, FULL, "campaign.sqlite", "run the command again")
    rc, out, _ = run(capsys, "verify", processed_copy)  # no half-written result: at most stale
    assert f"STALE epoch {label}" in out or "STALE" not in out
    assert "DAMAGED" not in out and "UNLISTED" not in out
    assert run(capsys, "process", processed_copy)[0] in (0, 3)
    assert tables(processed_copy) == reference


@pytest.mark.parametrize("command", ["report", "export-xlsx", "export-csv", "displacements"])
def test_a_full_disk_while_writing_an_output_is_one_line_and_leaves_no_file(processed_copy, tmp_path, capsys,
                                                                           monkeypatch, command):
    out = tmp_path / "out" / {"report": "r.pdf", "export-xlsx": "all.xlsx", "export-csv": "d.csv",
                              "displacements": "d.csv"}[command]
    out.parent.mkdir()
    argv = {"report": ("report", processed_copy, "--out", out), "export-xlsx": ("export", processed_copy, "--out", out),
            "export-csv": ("export", processed_copy, "--out", out),
            "displacements": ("displacements", processed_copy, "--out", out)}[command]
    before = snapshot(processed_copy)
    with file_full(monkeypatch, _partial_output):
        rc, _, err = run(capsys, *argv)
    assert rc == 1
    one_line(err, FULL, str(out))
    assert list(out.parent.iterdir()) == [] and snapshot(processed_copy) == before
    assert run(capsys, *argv)[0] == 0 and out.stat().st_size > 0


@pytest.fixture
def small_disk(tmp_path):
    """A 48 MB tmpfs (skipped where mounting is refused)."""
    mnt = tmp_path / "disk"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=48m", "tmpfs", str(mnt)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here ({r.stderr.decode().strip()})")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def _fill(disk: Path, leave: int = 0) -> Path:
    """Fill the disk to ``leave`` bytes free with one file (removed to free the space)."""
    filler = disk / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    try:
        for block in (1 << 20, 4096, 1):
            while True:
                st = os.statvfs(disk)
                if st.f_bavail * st.f_frsize - block < leave:
                    break
                try:
                    os.write(fd, b"\0" * block)
                except OSError:
                    break
    finally:
        os.close(fd)
    return filler


def test_a_real_full_disk(processed, small_disk, tmp_path, capsys):
    camp = small_disk / "camp"
    shutil.copytree(processed, camp, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    label = make_stale(camp)
    coarse, fine = stored_scans(camp, "2026-03-02")
    new_coarse = variant(coarse, tmp_path / "c.laz")  # on another disk
    before = snapshot(camp)
    # a writer killed after its commit leaves its change in the write-ahead log (not yet in the database file)
    subprocess.run([sys.executable, "-c", "import os, sqlite3, sys\n"
                    "c = sqlite3.connect(sys.argv[1]); c.execute('PRAGMA wal_autocheckpoint = 0')\n"
                    "from projects.store.digests import row_digest\n"
                    "c.execute(\"UPDATE meta SET value = 'Renamed bridge', digest = ? WHERE key = 'name'\",\n"
                    "          (row_digest('meta', ('name', 'Renamed bridge')),)); c.commit()\n"
                    "os._exit(0)", str(camp / DB_NAME)], check=True)
    assert (camp / (DB_NAME + "-wal")).stat().st_size > 0
    filler = _fill(small_disk)
    assert os.statvfs(small_disk).f_bavail == 0
    # read-only commands still read at 0 bytes free, the log's change included
    rc, out, err = run(capsys, "status", camp)
    assert rc == 0 and "not a readable" not in err and label in out and "campaign 'Renamed bridge'" in out
    filler.unlink()
    assert run(capsys, "status", camp)[0] == 0  # the log checkpointed (a reader may), then an empty log
    filler = _fill(small_disk)
    rc, out, err = run(capsys, "status", camp)
    assert rc == 0 and "campaign 'Renamed bridge'" in out, err
    assert run(capsys, "displacements", camp)[0] == 0
    rc, out, _ = run(capsys, "verify", camp)
    assert "DAMAGED" not in out
    # every writing command is one line, the campaign unchanged
    for argv in (("add-epoch", camp, "--date", "2026-03-23", "--coarse", new_coarse), ("process", camp),
                 ("report", camp, "--out", small_disk / "r.pdf"), ("export", camp, "--out", small_disk / "a.xlsx"),
                 ("settings", camp, "min_points", "900")):
        rc, _, err = run(capsys, *argv)
        assert rc == 1, argv
        one_line(err, FULL, "free")
    # a little room: the import is refused before it copies, and a write that runs out midway leaves nothing
    filler.unlink()
    filler = _fill(small_disk, leave=2 << 20)
    st = os.statvfs(small_disk)
    missing = math.ceil((new_coarse.stat().st_size + (1 << 20) - st.f_bavail * st.f_frsize) / (1 << 20))
    rc, _, err = run(capsys, "add-epoch", camp, "--date", "2026-03-23", "--coarse", new_coarse)
    assert rc == 1
    one_line(err, FULL, f"{camp / 'scans'}: free {missing} MB")
    filler.unlink()
    filler = _fill(small_disk, leave=16 << 10)
    for argv in (("export", camp, "--out", small_disk / "a.xlsx"), ("report", camp, "--out", small_disk / "r.pdf")):
        rc, _, err = run(capsys, *argv)
        assert rc == 1
        one_line(err, FULL, str(argv[-1]))
    assert sorted(p.name for p in small_disk.iterdir()) == ["camp", "filler"]  # no output, no partial file
    filler.unlink()
    conn = sqlite3.connect(camp / DB_NAME)  # the name back as it was, row for row
    with conn:
        conn.execute("UPDATE meta SET value = 'Test bridge', digest = ? WHERE key = 'name'",
                     (digests.row_digest("meta", ("name", "Test bridge")),))
    conn.close()
    assert snapshot(camp) == before
    assert run(capsys, "process", camp)[0] in (0, 3)
    assert tables(camp) == tables(processed)


def test_a_campaign_on_a_read_only_medium_is_read_and_writers_get_one_line(processed, small_disk, capsys):
    camp = small_disk / "camp"
    shutil.copytree(processed, camp, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    r = subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], capture_output=True)
    if r.returncode != 0:
        pytest.skip("cannot remount read-only here")
    rc, out, err = run(capsys, "status", camp)
    assert rc == 0 and "campaign 'Test bridge'" in out, err
    assert run(capsys, "verify", camp)[0] == 0
    rc, _, err = run(capsys, "settings", camp, "min_points", "900")
    assert rc == 1
    one_line(err, "cannot be opened to lock the campaign")


# ------------------------------------------------------------------------------------------ flipped bytes
def test_flipped_bytes_in_stored_results_are_found_by_verify_and_recomputed_by_process(processed_copy, tmp_path,
                                                                                      capsys):
    reference = tables(processed_copy)
    with Campaign.open(processed_copy, writable=False) as c:
        labels = [e.label for e in c.epochs()]
        value = next(d.displacement_m for d in c.displacements() if d.epoch == labels[-1] and d.displacement_m)
        blob = c.conn.execute("SELECT arrays FROM map_previews WHERE epoch = ?", (labels[0],)).fetchone()[0]
    db = processed_copy / DB_NAME
    assert not (processed_copy / (DB_NAME + "-wal")).exists()
    data = bytearray(db.read_bytes())
    at = data.find(struct.pack(">d", value))
    assert at > 0 and data.find(struct.pack(">d", value), at + 1) < 0
    data[at:at + 8] = struct.pack(">d", value + 0.002)  # 8 bytes inside one stored displacement
    at = data.find(blob[len(blob) // 2:len(blob) // 2 + 64])
    assert at > 0
    data[at:at + 16] = bytes(16)  # 16 bytes inside the first epoch's map preview
    db.write_bytes(bytes(data))

    rc, out, _ = run(capsys, "status", processed_copy)
    assert rc == 0 and f"{value * 1000 + 2:.4f}" not in out and "damaged (fails its checksum)" in out
    assert run(capsys, "report", processed_copy, "--out", tmp_path / "r.pdf")[0] == 0  # no BadZipFile
    rc, out, _ = run(capsys, "verify", processed_copy)
    assert rc == 3
    assert f"DAMAGED displacements of epoch {labels[-1]}" in out and f"DAMAGED map preview of epoch {labels[0]}" in out
    rc, out, _ = run(capsys, "process", processed_copy)
    assert rc in (0, 3) and re.search(rf"^{labels[-1]}\s+(processed|measured)\b", out, re.M), out
    assert run(capsys, "verify", processed_copy)[0] == 0
    assert tables(processed_copy) == reference
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.map_preview(labels[0]) is not None


# ------------------------------------------------------------------------------------------ schema version
@pytest.mark.parametrize("value", ["abc", "0", "99", None, "6"])
def test_a_damaged_schema_version_is_one_line_and_repair_sets_it_from_the_tables(processed_copy, tmp_path, capsys,
                                                                                 value):
    conn = sqlite3.connect(processed_copy / DB_NAME)
    with conn:
        if value is None:
            conn.execute("DELETE FROM meta WHERE key = 'schema_version'")
        else:
            conn.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (value,))
    conn.close()
    before = snapshot(processed_copy)
    word = "newer BridgeSurvey" if value == "99" else "campaign.sqlite has an unreadable schema version"
    for argv in (("status", processed_copy), ("process", processed_copy), ("verify", processed_copy),
                 ("report", processed_copy, "--out", tmp_path / "r.pdf")):
        rc, _, err = run(capsys, *argv)
        assert rc == 1
        one_line(err, word)
    assert snapshot(processed_copy) == before
    rc, out, err = run(capsys, "repair", processed_copy)
    if value == "99":
        assert rc == 1 and "update BridgeSurvey" in err and snapshot(processed_copy) == before
        return
    assert rc == 0 and f"schema version set to {schema.SCHEMA_VERSION} from the tables" in out
    assert run(capsys, "status", processed_copy)[0] == 0
    assert run(capsys, "verify", processed_copy)[0] == 0


# ------------------------------------------------------------------------------------------ a stale lock
#: A writer that takes the campaign's lock and holds it until it is killed (a command may be too quick to catch).
HOLD_LOCK = ("import sys, time\nfrom projects.store.campaign import Campaign\n"
             "c = Campaign.open(sys.argv[1])\ntime.sleep(120)\n")


def test_a_stale_lock_left_by_a_killed_writer_blocks_nobody(processed_copy, capsys):
    proc = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(processed_copy)], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    lock = processed_copy / ".lock"
    deadline = time.time() + 30
    while time.time() < deadline and not (lock.exists() and f'"pid": {proc.pid}' in lock.read_text(errors="replace")):
        time.sleep(0.01)
    assert proc.poll() is None, "the command finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    rc, out, err = run(capsys, "status", processed_copy)
    assert rc == 0, err
    rc, _, err = run(capsys, "settings", processed_copy, "min_points", "900")  # a writer too
    assert rc == 0, err
    assert str(proc.pid) not in lock.read_text()


# ------------------------------------------------------------------------------------------ kill -9
def _writing_commands(camp: Path, tmp_path: Path) -> list[tuple[str, list[str]]]:
    coarse, fine = stored_scans(camp, "2026-03-02")
    c4, f4, f3 = (variant(coarse, tmp_path / "k" / "c4.laz"), variant(fine, tmp_path / "k" / "f4.laz"),
                  variant(fine, tmp_path / "k" / "f3.laz", 2))
    cam = camera_csv(tmp_path / "k" / "cam.csv")
    return [("add-epoch", ["add-epoch", str(camp), "--date", "2026-03-23", "--coarse", str(c4), "--fine", str(f4)]),
            ("add-fine", ["add-fine", str(camp), "--epoch", "2026-03-16", str(f3)]),
            ("camera import", ["camera", "import", str(camp), str(cam)]),
            ("process", ["process", str(camp)]),
            ("settings", ["settings", str(camp), "min_points", "900"]),
            ("report", ["report", str(camp), "--out", str(tmp_path / "k" / "r.pdf")]),
            ("export", ["export", str(camp), "--out", str(tmp_path / "k" / "a.xlsx")]),
            ("repair", ["repair", str(camp)])]


@pytest.mark.slow
def test_kill_9_at_random_moments_of_every_writing_command_loses_nothing(processed_copy, tmp_path, capsys):
    rng = random.Random(29)
    camp = processed_copy
    for name, argv in _writing_commands(camp, tmp_path):
        delay = rng.uniform(0.8, 3.0)  # from the interpreter's start to the middle of the work
        proc = subprocess.Popen(CLI + argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
        proc.wait()
        with Campaign.open(camp, writable=False) as c:
            assert c.integrity_check() == "ok", name
            assert c.damaged_results() == [], name
            listed = c.listed_files()
        entries = journal.latest_by_path(camp)
        for rel in imports.folder_files(camp):  # a file the database does not list is one the journal knows
            assert rel in listed or rel in entries, (name, rel)
        assert not [p for p in (tmp_path / "k").iterdir() if ".part" in p.name], name
        rc, _, err = run(capsys, *argv)  # the same command, run again, completes (an import done is refused)
        assert rc in (0, 3) or "already" in err, (name, err)  # "already": the killed run had committed
    rc, out, _ = run(capsys, "verify", camp)
    assert "DAMAGED" not in out and "UNLISTED" not in out, out

"""The campaign store: a folder with an SQLite database and the imported scan files.

Layout of a campaign folder::

    campaign.sqlite      schema-versioned database (WAL, foreign keys)
    scans/               imported scan files, copied once, read-only, named by checksum
    camera/              imported camera displacement series, the same way
    .lock                held by the process working on the campaign

Every change is one transaction; files are written under a temporary name and
renamed, so a process killed at any moment leaves a valid campaign, and
running the same command again completes the work.
"""
from __future__ import annotations

import contextlib
import datetime as dt
import json
import os
import sqlite3
import uuid
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from common.errors import SurveyError
from common.files import (
    MB,
    disk_full_error,
    ensure_free,
    is_disk_full,
    remove_stale_temp_files,
    sha256_of,
    write_atomic,
)
from common.series import check_zone
from lidar.centroid import TargetCentroid
from lidar.layout import Layout, check_layout
from lidar.plan import ScanPlan
from lidar.scanner_catalogue import DEFAULT_SCANNER, get_scanner
from lidar.scanner_profile import ScannerProfile
from lidar.systematic.adjustment import FieldModel
from projects.store import digests, field_tables, inputs, journal, schema, setup_tables, wal
from projects.store.connection import connect, open_database
from projects.store.errors import CampaignError, CampaignLockedError, DuplicateImportError, InputError
from projects.store.imports import (  # noqa: F401  (importers name them here)
    CAMERA_DIR,
    ENV_DIR,
    IMPORT_DIRS,
    PREDICTION_DIR,
    SCANS_DIR,
    Copied,
    clean_temp_files,
    copy_in,
    folder_files,
    header_facts,
    link_by_visit,
    not_writable,
    remove_uncommitted,
    visit_link_name,
)
from projects.store.limits import Limit, parse_rule
from projects.store.lock import LOCK_NAME, CampaignLock  # noqa: F401  (LOCK_NAME: likewise)
from projects.store.records import (
    CheckVerdict,
    DisplacementRecord,
    DisplacementSet,
    Epoch,
    EpochInputs,
    EpochResult,
    LimitRecord,
    LogEntry,
    ReferenceCheck,
    Reflector,
    ScanFile,
    StoredPlan,
    now_iso,
)
from projects.store.repositories import (
    ComparisonRepository,
    CrossvalRepository,
    EventRepository,
    PredictionRepository,
    SeriesRepository,
)

DB_NAME = "campaign.sqlite"
#: The campaign's field model as a file for other tools (versioned JSON, :meth:`FieldModel.to_json`).
BIAS_FILE = "bias.json"


def parse_datetime(text: str) -> str:
    """Normalise an ISO 8601 date or date-time; naive values are taken as UTC."""
    try:
        value = dt.datetime.fromisoformat(str(text).strip().replace("Z", "+00:00"))
    except ValueError as exc:
        if "isoformat" not in str(exc):  # ISO 8601 in form, but no such day or time (2027-02-30, 24:30)
            raise InputError(f"date {text!r} is an impossible date: {exc}") from None
        raise InputError(f"date {text!r} is not ISO 8601 (e.g. 2026-03-14 or 2026-03-14T09:30)") from None
    if value.tzinfo is None:
        value = value.replace(tzinfo=dt.UTC)
    return value.isoformat()


def _normal_values(n) -> tuple:
    """A layout normal as three SQL values (NULLs when unknown)."""
    return tuple(float(v) for v in n) if np.all(np.isfinite(n)) else (None, None, None)


def _nan(v) -> float:
    return float("nan") if v is None else float(v)


#: The log's actions that make an epoch's check verdict (see :func:`_verdict_of`).
_VERDICT_ACTIONS = "('check', 'check-accepted', 'import')"


def _verdict_of(epoch: str, rows) -> CheckVerdict | None:
    """The check verdict of an epoch from its log rows of :data:`_VERDICT_ACTIONS`, in order (see check_verdict)."""
    latest: dict[int, tuple[str, dict]] = {}
    accepted = False
    for r in rows:
        d = json.loads(r["details"])
        if r["action"] == "check":
            latest[int(d.get("setup", 1))] = (r["time"], d)
            accepted = False
        elif r["action"] == "check-accepted":
            accepted = True
        elif d.get("role") == "fine" and latest:  # fine scans added after the check: it no longer holds
            latest.clear()
            accepted = False
    if not latest:
        return None
    reasons = {t: why for _, d in latest.values() for t, why in d.get("rescan", {}).items()}
    return CheckVerdict(epoch, max(t for t, _ in latest.values()), tuple(reasons), reasons,
                        any(d.get("drifted") for _, d in latest.values()), accepted)


class Campaign:
    """An open campaign. Use :meth:`create` or :meth:`open`, preferably as a context manager.

    The campaign owns the connection, the lock and the transactions, and the core tables (epochs,
    their files, plans, centroids and displacements, reflectors, limits, settings, the log). The
    other tables are behind repositories hanging off it:

    ``series``
        camera and environment series (:class:`~projects.store.repositories.SeriesRepository`);
    ``events``, ``predictions``, ``crossvals``, ``comparisons``
        events, design predictions, camera cross-validations, whole-scan comparisons.
    """

    def __init__(self, folder: Path, conn: sqlite3.Connection, lock: CampaignLock | None, *, writable: bool):
        self.folder = folder
        self.conn = conn
        self._lock = lock
        self.writable = writable
        self._sound: dict[tuple, bool] = {}
        self._sound_at = -1
        self._records: tuple[tuple, list[DisplacementRecord]] | None = None  # displacements(), and when read
        self.series = SeriesRepository(self)
        self.events = EventRepository(self)
        self.predictions = PredictionRepository(self)
        self.crossvals = CrossvalRepository(self)
        self.comparisons = ComparisonRepository(self)

    # ------------------------------------------------------------------ opening
    @classmethod
    def create(cls, folder: str | os.PathLike, *, name: str, layout: Layout, span_m: float | None = None,
               profile: ScannerProfile | None = None, timezone: str = "UTC") -> Campaign:
        """Create a new campaign folder (which must not hold a campaign yet).

        ``profile`` is the scanner (default: the catalogue's Riegl VZ-1000, the dissertation's); ``timezone`` the
        zone of imported times without an offset (:attr:`timezone`).
        """
        if profile is None:
            profile = get_scanner(DEFAULT_SCANNER)
        folder = Path(folder)
        if not name.strip():
            raise InputError("the campaign needs a name (--name)")
        if span_m is not None and not (np.isfinite(span_m) and span_m > 0):
            raise InputError(f"span length must be positive, got {span_m}")
        check_layout(layout)
        timezone = check_zone(timezone)
        if (folder / DB_NAME).exists():
            raise CampaignError(f"{folder}: already holds a campaign; open it instead of creating one")
        if folder.exists() and not folder.is_dir():
            raise CampaignError(f"{folder}: exists and is not a folder")
        folder.mkdir(parents=True, exist_ok=True)
        (folder / SCANS_DIR).mkdir(exist_ok=True)
        tmp = folder / f".{DB_NAME}.{uuid.uuid4().hex}.part"
        conn = connect(tmp)
        try:
            schema.create(conn)
            with conn:
                meta = {"name": name.strip(), "span_m": "" if span_m is None else repr(float(span_m)),
                        "scanner_profile": json.dumps(profile.to_dict()), "created": now_iso(),
                        "settings": json.dumps({"timezone": timezone})}
                conn.executemany("INSERT INTO meta(key, value) VALUES (?, ?)", meta.items())
                conn.executemany(
                    "INSERT INTO reflectors(id, grp, x, y, z, diameter_m, nx, ny, nz) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    [(i, g, *map(float, p), float(d), *_normal_values(n)) for i, g, p, d, n in
                     zip(layout.ids, layout.groups, layout.xyz, layout.diameters_m, layout.normals, strict=False)])
                conn.execute("INSERT INTO log(time, action, epoch, details) VALUES (?, 'init', NULL, ?)",
                             (now_iso(), json.dumps({"name": name, "reflectors": len(layout)})))
                digests.seal_rows(conn, "meta")
                digests.seal_rows(conn, "reflectors")
            conn.close()
            os.replace(tmp, folder / DB_NAME)
        except BaseException:
            conn.close()
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise
        return cls.open(folder)

    @classmethod
    def open(cls, folder: str | os.PathLike, *, writable: bool = True) -> Campaign:
        """Open a campaign; a writer holds an exclusive lock, readers a shared one (see :mod:`projects.store.lock`).

        A damaged or unknown schema version, a damaged database and a full disk are each one line
        (:class:`CampaignError`, :class:`~common.files.DiskFullError`); readers still read at 0 bytes free.
        """
        folder = Path(folder)
        db = folder / DB_NAME
        if not db.is_file():
            raise CampaignError(f"{folder}: no campaign here (no {DB_NAME}); create one with 'bridgesurvey init'")
        if writable:  # a write would fail at its end (SQLite's 'attempt to write a readonly database'): say so now
            for p in (folder, db):
                if not os.access(p, os.W_OK) and not os.statvfs(p).f_flag & os.ST_RDONLY:  # a medium: the lock says
                    raise not_writable(p)
        lock = CampaignLock.acquire(folder, exclusive=writable)
        try:
            wal.check(db)  # before SQLite reads the log: a restored database never reads another one's
            conn = open_database(db, writable=writable)
            try:
                wal.no_automatic_checkpoints(conn)
                cls._upgrade(conn, lock, folder, writable)
                if writable:
                    wal.checkpoint(conn, db)
            except BaseException:
                conn.close()
                raise
        except BaseException:
            lock.release()
            raise
        camp = cls(folder, conn, lock, writable=writable)
        if writable:
            camp._clean_temp_files()
        return camp

    @staticmethod
    def _upgrade(conn: sqlite3.Connection, lock: CampaignLock, folder: Path, writable: bool) -> None:
        """Check the schema version and migrate an older campaign (a reader under a brief exclusive lock)."""
        version = schema.version_of(conn, str(folder))
        if version > schema.SCHEMA_VERSION:
            raise CampaignError(f"{folder}: written by a newer BridgeSurvey (schema {version}, this one reads up to "
                                f"{schema.SCHEMA_VERSION}); update BridgeSurvey")
        if version == schema.SCHEMA_VERSION:
            return
        try:
            if not writable:
                lock.upgrade()
            schema.migrate(conn, version)
            if not writable:
                lock.downgrade()
            schema.check_tables(conn, str(folder))
        except BlockingIOError:
            raise CampaignLockedError(f"{folder}: the campaign needs a schema upgrade but another process is "
                                      "using it; try again when it has finished") from None

    def close(self) -> None:
        if self.conn is not None:
            if self.writable and not self.conn.in_transaction:
                with contextlib.suppress(SurveyError, sqlite3.Error):  # else SQLite checkpoints as it closes
                    wal.checkpoint(self.conn, self.folder / DB_NAME)
            self.conn.close()
            self.conn = None  # type: ignore[assignment]  # a closed campaign has no connection
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def __enter__(self) -> Campaign:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @contextlib.contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """One atomic change: everything inside commits together or not at all."""
        if not self.writable:
            raise CampaignError("the campaign is open read-only")
        with self.conn:
            yield self.conn

    @contextlib.contextmanager
    def snapshot(self) -> Iterator[sqlite3.Connection]:
        """Several reads seen at one moment (one read transaction; inside a transaction, that one)."""
        if self.conn.in_transaction:
            yield self.conn
            return
        self.conn.execute("BEGIN")
        try:
            yield self.conn
        finally:
            if self.conn.in_transaction:
                self.conn.execute("COMMIT")

    def _clean_temp_files(self) -> None:
        """Remove the temporary files an interrupted import left (never an imported file: see :mod:`.imports`)."""
        clean_temp_files(self.folder, DB_NAME)
        remove_stale_temp_files(self.folder)  # outputs a killed command was writing here (bias.json...)

    def check_still_there(self) -> None:
        """Raise the one line when the campaign folder is gone from where it was opened (moved, renamed, deleted)."""
        if not (self.folder / DB_NAME).is_file():
            raise CampaignError(f"{self.folder}: the campaign folder is no longer there (moved, renamed or deleted "
                                "while the command ran); what was saved before is kept whole: run the command again "
                                "where the folder is now")

    def listed_files(self) -> set[str]:
        """Every file of the import folders the database lists (paths relative to the campaign)."""
        return {r[0] for table in IMPORT_DIRS.values() for r in self.conn.execute(f"SELECT stored_path FROM {table}")}

    def unlisted_files(self) -> list[str]:
        """Files in the import folders that the database does not list (after restoring an older database).

        They are never removed: ``verify`` lists them and ``repair`` registers them again.
        """
        listed = self.listed_files()
        return sorted(rel for rel in folder_files(self.folder) if rel not in listed)

    # ------------------------------------------------------------------ metadata
    def meta(self, key: str, default: str = "") -> str:
        """One campaign-level value of the ``meta`` table (``default`` when it is not set).

        A value that fails its digest is a :class:`CampaignError` naming it (never served).
        """
        row = self.conn.execute("SELECT key, value, digest FROM meta WHERE key = ?", (key,)).fetchone()
        if row is None:
            return default
        self._check_row("meta", row)
        return row["value"]

    def set_meta(self, key: str, value: str) -> None:
        """Set one campaign-level value (``meta`` table), in its own transaction."""
        with self.transaction() as c:
            c.execute("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", (key, value))
            digests.seal_row(c, "meta", key)

    def _check_row(self, table: str, row: sqlite3.Row) -> None:
        """Raise the one line naming an input row that fails its digest (see :data:`digests.INPUTS`)."""
        if not digests.row_is_sound(table, row):
            raise CampaignError(damaged_input_line(self.folder, table, row[digests.INPUTS[table].key]))

    def damaged_inputs(self) -> list[tuple[str, str]]:
        """(table, key) of every input row that fails its digest (limits, epochs, reflectors, settings, field model)."""
        return [(table, key) for table in digests.INPUTS for key in digests.damaged_rows(self.conn, table)]

    @property
    def name(self) -> str:
        return self.meta("name", "")

    @property
    def span_m(self) -> float | None:
        v = self.meta("span_m", "")
        return float(v) if v else None

    @property
    def profile(self) -> ScannerProfile:
        return ScannerProfile.from_dict(json.loads(self.meta("scanner_profile", "{}")))

    def profile_for(self, label: str | None, setup: int = 1) -> ScannerProfile:
        """The scanner of an epoch's set-up: its own (``add-setup --scanner``), else the epoch's, else the campaign's."""
        return _profile_of(self.settings(), label, setup, self.profile)

    def set_profile(self, profile: ScannerProfile, *, epoch: str | None = None, setup: int | None = None) -> None:
        """Set the campaign's scanner, or one epoch's, or one set-up's of an epoch (which must exist)."""
        if epoch is None:
            with self.transaction() as c:
                c.execute("UPDATE meta SET value = ? WHERE key = 'scanner_profile'", (json.dumps(profile.to_dict()),))
                digests.seal_row(c, "meta", "scanner_profile")
                self.log_action(c, "scanner", None, {"name": profile.name})
            return
        self.epoch(epoch)
        s = self.settings()
        entry: dict = {"kind": "epoch-scanner", "epoch": epoch, "profile": profile.to_dict(), "stored_path": "",
                       "imported": now_iso()}
        if setup is None or setup == 1:
            s.setdefault("epoch_scanners", {})[epoch] = profile.to_dict()
        else:
            self.check_setup(epoch, setup)
            s.setdefault("setup_scanners", {}).setdefault(epoch, {})[str(setup)] = profile.to_dict()
            entry["setup"] = setup
        mark = self.append_journal(entry)  # for 'repair'
        try:
            with self.transaction() as c:
                c.execute("UPDATE meta SET value = ? WHERE key = 'settings'", (json.dumps(s),))
                digests.seal_row(c, "meta", "settings")
                self.log_action(c, "scanner", epoch, {"name": profile.name, **({"setup": setup} if "setup" in entry else {})})
        except BaseException:
            journal.truncate(self.folder, mark)
            raise

    def settings(self) -> dict:
        return json.loads(self.meta("settings", "{}"))

    def set_setting(self, key: str, value) -> None:
        s = self.settings()
        s[key] = value
        with self.transaction() as c:
            c.execute("UPDATE meta SET value = ? WHERE key = 'settings'", (json.dumps(s),))
            digests.seal_row(c, "meta", "settings")
            self.log_action(c, "setting", None, {key: value})

    @property
    def timezone(self) -> str:
        """The campaign's time zone: imported times without an offset are read in it (IANA name or +hh:mm)."""
        return str(self.settings().get("timezone") or "UTC")

    def set_timezone(self, name: str) -> None:
        """Change :attr:`timezone` (series imported before keep the zone they were read in)."""
        self.set_setting("timezone", check_zone(name))

    def log_action(self, conn: sqlite3.Connection, action: str, epoch: str | None, details: dict) -> None:
        """Add a line to the campaign's log inside the transaction ``conn``."""
        conn.execute("INSERT INTO log(time, action, epoch, details) VALUES (?, ?, ?, ?)",
                     (now_iso(), action, epoch, json.dumps(details, default=str)))

    # ------------------------------------------------------------------ the on-site check's verdict
    def save_check_verdict(self, epoch: str, *, setup: int, rescan: dict[str, str], drifted: bool) -> None:
        """Record what the check of ``epoch`` (set-up ``setup``) said.

        ``rescan`` maps each target it asked to re-scan to why. Kept in the campaign's log (no table of its own);
        :meth:`check_verdict` reads it back.
        """
        self.epoch(epoch)
        with self.transaction() as c:
            self.log_action(c, "check", epoch, {"setup": int(setup), "rescan": dict(rescan), "drifted": bool(drifted)})

    def accept_check(self, epoch: str) -> None:
        """The user processes ``epoch`` as it is, although its check asked for a re-scan (logged)."""
        verdict = self.check_verdict(epoch)
        with self.transaction() as c:
            self.log_action(c, "check-accepted", epoch, {"rescan": list(verdict.rescan) if verdict else []})

    def check_verdict(self, epoch: str) -> CheckVerdict | None:
        """What the check last said of ``epoch``'s fine scans, or None.

        None: never checked, or fine scans were added since (the re-scan came in, the old verdict no longer holds).
        With several set-ups, each set-up's latest check counts; the targets to re-scan are all of theirs.
        """
        rows = self.conn.execute("SELECT id, time, action, details FROM log WHERE epoch = ? AND action IN "
                                 f"{_VERDICT_ACTIONS} ORDER BY id", (epoch,)).fetchall()
        return _verdict_of(epoch, rows)

    def check_verdicts(self) -> dict[str, CheckVerdict]:
        """Every epoch's :meth:`check_verdict` that is not None, from one read of the log (label -> verdict).

        The campaign's log grows with every action; asking it one epoch at a time reads all of it each time.
        """
        by_epoch: dict[str, list] = {}
        for r in self.conn.execute("SELECT epoch, id, time, action, details FROM log WHERE action IN "
                                   f"{_VERDICT_ACTIONS} AND epoch IS NOT NULL ORDER BY id"):
            by_epoch.setdefault(r["epoch"], []).append(r)
        return {ep: v for ep, rows in by_epoch.items() if (v := _verdict_of(ep, rows)) is not None}

    def log(self) -> list[LogEntry]:
        """The campaign's log, oldest first."""
        return [LogEntry(r["id"], r["time"], r["action"], r["epoch"], json.loads(r["details"]))
                for r in self.conn.execute("SELECT * FROM log ORDER BY id")]

    def last_revisions(self) -> LogEntry | None:
        """The newest ``revisions`` entry of the log (stored values that processing changed), or None."""
        r = self.conn.execute("SELECT * FROM log WHERE action = 'revisions' ORDER BY id DESC LIMIT 1").fetchone()
        return None if r is None else LogEntry(r["id"], r["time"], r["action"], r["epoch"], json.loads(r["details"]))

    # ------------------------------------------------------------------ reflectors
    def reflectors(self) -> list[Reflector]:
        """Every reflector, retired ones included: reference targets first, then by id."""
        rows = self.conn.execute("SELECT * FROM reflectors ORDER BY grp DESC, id").fetchall()
        for r in rows:
            self._check_row("reflectors", r)
        return [_reflector(r) for r in rows]

    def reflector(self, rid: str) -> Reflector:
        row = self.conn.execute("SELECT * FROM reflectors WHERE id = ?", (rid,)).fetchone()
        if row is None:
            known = ", ".join(r.id for r in self.reflectors())
            raise InputError(f"unknown reflector {rid!r}; the campaign has {known}")
        self._check_row("reflectors", row)
        return _reflector(row)

    def layout(self, at: str | None = None) -> Layout:
        """Reflectors expected at a date-time (all active ones when None)."""
        return _layout_of(self.reflectors(), at)

    def layout_warnings(self, epoch: str | None = None) -> list[str]:
        """Warnings about the layout (at an epoch's date, with its scanner).

        Too few reference targets (:func:`inputs.few_references`), and targets no station could reach.
        """
        at = self.epoch(epoch).datetime if epoch else None
        layout, profile = self.layout(at), self.profile_for(epoch)
        return inputs.few_references(layout.ids_in("reference")) + inputs.unreachable_targets(
            layout.ids, layout.xyz, max_range_m=float(profile.max_range_m), scanner=f"the {profile.name}")

    def add_reflector(self, rid: str, group: str, xyz: Sequence[float], *, diameter_m: float = 0.05,
                      installed: str | None = None, replaces: str | None = None, note: str = "") -> None:
        if group not in ("reference", "measurement"):
            raise InputError(f"group must be 'reference' or 'measurement', not {group!r}")
        if not rid.strip():
            raise InputError("a reflector needs an id")
        if self.conn.execute("SELECT 1 FROM reflectors WHERE id = ?", (rid,)).fetchone():
            raise InputError(f"reflector {rid!r} already exists; choose a new id")
        xyz = [float(v) for v in xyz]
        if len(xyz) != 3 or not np.all(np.isfinite(xyz)) or not (diameter_m > 0):
            raise InputError("reflector coordinates must be three finite numbers and the diameter positive")
        installed = parse_datetime(installed) if installed else None
        with self.transaction() as c:
            c.execute("INSERT INTO reflectors(id, grp, x, y, z, diameter_m, installed, replaces, note) "
                      "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", (rid, group, *xyz, diameter_m, installed, replaces, note))
            digests.seal_row(c, "reflectors", rid)
            self.log_action(c, "reflector-add", None, {"id": rid, "group": group, "replaces": replaces})

    def retire_reflector(self, rid: str, when: str) -> None:
        r = self.reflector(rid)
        if r.retired:
            raise InputError(f"reflector {rid!r} was already retired on {r.retired}")
        when = parse_datetime(when)
        with self.transaction() as c:
            c.execute("UPDATE reflectors SET retired = ? WHERE id = ?", (when, rid))
            digests.seal_row(c, "reflectors", rid)
            self.log_action(c, "reflector-retire", None, {"id": rid, "when": when})

    def replace_reflector(self, old: str, new: str, when: str, *, xyz: Sequence[float] | None = None) -> None:
        """Retire ``old`` and install ``new`` at the same place (or at ``xyz``); the history continues."""
        r = self.reflector(old)
        when = parse_datetime(when)
        with self.transaction() as c:
            if self.conn.execute("SELECT 1 FROM reflectors WHERE id = ?", (new,)).fetchone():
                raise InputError(f"reflector {new!r} already exists; choose a new id")
            pos = [float(v) for v in (xyz if xyz is not None else r.xyz_layout)]
            c.execute("UPDATE reflectors SET retired = ? WHERE id = ?", (when, old))
            c.execute("INSERT INTO reflectors(id, grp, x, y, z, diameter_m, installed, replaces, note, nx, ny, nz) "
                      "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                      (new, r.group, *pos, r.diameter_m, when, old, f"replaces {old}", *_normal_values(r.normal_layout)))
            digests.seal_row(c, "reflectors", old)
            digests.seal_row(c, "reflectors", new)
            self.log_action(c, "reflector-replace", None, {"old": old, "new": new, "when": when})

    # ------------------------------------------------------------------ epochs and files
    def epochs(self) -> list[Epoch]:
        """Every epoch, oldest first."""
        rows = self.conn.execute("SELECT * FROM epochs ORDER BY datetime, label").fetchall()
        for r in rows:
            self._check_row("epochs", r)
        return [_epoch(r) for r in rows]

    def epoch(self, label: str) -> Epoch:
        """One epoch; an unknown label is an :class:`InputError` naming the epochs there are."""
        row = self.conn.execute("SELECT * FROM epochs WHERE label = ?", (label,)).fetchone()
        if row is None:
            labels = [e.label for e in self.epochs()]
            hint = f"; epochs are {', '.join(labels[-8:])}" if labels else "; the campaign has no epochs yet"
            raise InputError(f"no epoch {label!r} in {self.folder}{hint}")
        self._check_row("epochs", row)
        return _epoch(row)

    def files(self, epoch: str, role: str | None = None, *, setup: int | None = 1) -> list[ScanFile]:
        """An epoch's scan files (``role`` ``"coarse"`` or ``"fine"``, or both), in import order.

        ``setup`` chooses the set-up (default 1: one scanner frame, as every visit had before set-ups);
        None gives every set-up's files.
        """
        q = "SELECT * FROM files WHERE epoch = ?" + (" AND role = ?" if role else "") + " ORDER BY imported, stored_path"
        rows = [ScanFile(**dict(r)) for r in self.conn.execute(q, (epoch, role) if role else (epoch,))]
        return rows if setup is None else [f for f in rows if setup in f.setups]

    def setups(self, epoch: str) -> list[int]:
        """The set-ups of an epoch, 1-based ([1] for an epoch of one set-up)."""
        return sorted({k for f in self.files(epoch, setup=None) for k in f.setups}) or [1]

    def last_setup(self, epoch: str) -> int:
        """The set-up added last to an epoch (the default of ``--setup``)."""
        self.epoch(epoch)
        return self.setups(epoch)[-1]

    def check_setup(self, epoch: str, setup: int) -> int:
        """``setup`` when the epoch has it, else an :class:`InputError` naming the set-ups there are."""
        have = self.setups(epoch)
        if setup not in have:
            raise InputError(f"epoch {epoch} has no set-up {setup}; its set-ups are {', '.join(map(str, have))} "
                             "(add one with 'bridgesurvey add-setup')")
        return setup

    def epoch_inputs(self, label: str, *, plan: bool = True, setup: int = 1) -> EpochInputs:
        """In one read: the epoch, a set-up's files by role, its stored plan and result, the layout, scanner, settings.

        An unknown label is an :class:`InputError`. ``plan=False`` does not read the plan (``plan`` is
        then None), for callers that only compare hashes. ``setup`` is the set-up (default 1).
        """
        with self.snapshot():
            return self._inputs_of(self.epoch(label), setup, plan, self.reflectors(), self.settings(), self.profile)

    def visits_inputs(self, *, plan: bool = False) -> dict[str, dict[int, EpochInputs]]:
        """Every epoch's :meth:`epoch_inputs`, each of its set-ups', in one read (label -> set-up -> inputs).

        The campaign's reflectors, settings and scanner are read once for all of them (what ``status`` and the
        application's opening need to tell which visits are stale: at 520 visits, once instead of 520 times).
        The epochs share their settings dict: read it, never change it.
        """
        out: dict[str, dict[int, EpochInputs]] = {}
        with self.snapshot():
            reflectors, settings, campaign = self.reflectors(), self.settings(), self.profile
            layouts: dict[tuple[str, ...], Layout] = {}  # one layout a set of reflectors expected, shared
            for ep in self.epochs():
                first = self._inputs_of(ep, 1, plan, reflectors, settings, campaign, layouts)
                out[ep.label] = {1: first, **{k: self._inputs_of(ep, k, plan, reflectors, settings, campaign, layouts)
                                              for k in first.setups if k != 1}}
        return out

    def _inputs_of(self, ep: Epoch, setup: int, plan: bool, reflectors: Sequence[Reflector], settings: dict,
                   campaign: ScannerProfile, layouts: dict | None = None) -> EpochInputs:
        """One set-up's :class:`EpochInputs`, the campaign-level rows given (inside the caller's snapshot)."""
        every = self.files(ep.label, setup=None)
        files = [f for f in every if setup in f.setups]
        stored = self.stored_plan(ep.label, setup) if plan else None
        result = self.result(ep.label, setup)
        profile = _profile_of(settings, ep.label, setup, campaign)
        setups = tuple(sorted({k for f in every for k in f.setups})) or (1,)
        expected = tuple(r.id for r in reflectors if r.expected_at(ep.datetime))
        layout = None if layouts is None else layouts.get(expected)
        if layout is None:
            layout = _layout_of(reflectors, ep.datetime)
            if layouts is not None:
                layouts[expected] = layout
        return EpochInputs(ep, tuple(f for f in files if f.role == "coarse"), tuple(f for f in files if f.role == "fine"),
                           stored, result, layout, profile, settings, setup, setups,
                           plan and self.preview_to_remake(ep.label, setup))

    def path_of(self, file: ScanFile) -> Path:
        """Where a stored scan file is on disk."""
        return self.folder / file.stored_path

    def import_file(self, src: Path, sha: str, sub: str, record, *, journal_entry: dict | None = None) -> str:
        """Copy ``src`` into ``sub`` read-only and, in one transaction, ``record(conn, stored_path)``.

        ``sha`` is the file's checksum when it was read; ``journal_entry`` says what the file was
        imported as, for the journal (:mod:`projects.store.journal`: a kind, and what it takes to read
        it again). On any failure nothing stays: no row, and no copy this import made.
        """
        copied: list[Copied] = []
        marks: list[int] = []
        try:
            got = copy_in(self.folder, src, sub)
            copied.append(got)
            if got.sha256 != sha:
                raise InputError(f"{src}: the file changed while it was being imported; try again")
            marks.append(self._journal(got, src, {"kind": sub, **(journal_entry or {})}))
            with self.transaction() as conn:
                record(conn, got.rel)
        except BaseException:
            self._undo_import(copied, marks)
            raise
        return got.rel

    def _undo_import(self, copied: list[Copied], marks: list[int]) -> None:
        """What an import that did not commit leaves: nothing (its copies and journal lines taken back)."""
        if marks:
            journal.truncate(self.folder, marks[0])
        remove_uncommitted(self.folder, copied)

    def _journal(self, copied: Copied, src: Path, entry: dict) -> int:
        """Write the journal line of a file about to be registered (before the transaction commits).

        Returns the journal's size before the line (see :func:`projects.store.journal.truncate`).
        """
        return self.append_journal({**entry, "stored_path": copied.rel, "sha256": copied.sha256, "size": copied.size,
                                    "original_path": str(src.resolve()), "imported": now_iso()})

    def append_journal(self, entry: dict) -> int:
        """Append ``entry`` to the campaign's journal (a full disk is one line); returns the journal's size before it.

        Writers call it before their transaction commits, and take the line back with
        :func:`projects.store.journal.truncate` when the transaction fails.
        """
        try:
            return journal.append(self.folder, entry)
        except OSError as exc:
            if is_disk_full(exc):
                raise disk_full_error(self.folder / journal.JOURNAL_NAME, MB) from None
            raise

    def import_files(self, epoch: str, paths: Iterable[str | os.PathLike], role: str, *,
                     validate=None, create_epoch: dict | None = None, setup: int | None = None,
                     frames_of=None) -> list[str]:
        """Validate, copy in and register scan files of an epoch, all or nothing.

        ``validate(path)`` must raise on an unreadable file (before anything is changed).
        ``create_epoch`` (label, datetime, notes) creates the epoch in the same transaction. ``setup`` is
        the set-up the files belong to (default: the last one added; a fine file whose scans carry a
        set-up's pose goes to that set-up). ``frames_of(path, fallback)`` (e.g. :func:`lidar.io.poses.file_frames`
        with the pose the user gave) reads a file and returns a :class:`lidar.io.poses.FileFrame` per scan
        position in it, raising on an unreadable file or one in a project frame without a pose;
        ``fallback`` is the set-up's own pose, when one is known. It replaces ``validate``.
        """
        return self._import(epoch, [(Path(p), role) for p in paths], setup=setup, validate=validate,
                            frames_of=frames_of, create_epoch=create_epoch)

    def _checked_new(self, items: Sequence[tuple[Path, str]]) -> list[str]:
        """The checksums of files about to be imported: each exists, none twice, none already imported."""
        for p, _ in items:
            if not p.is_file():
                raise InputError(f"{p}: no such file; check the path")
        shas = [sha256_of(p) for p, _ in items]
        if len(set(shas)) != len(shas):
            raise DuplicateImportError("the same file is given twice")
        for (p, _), sha in zip(items, shas, strict=False):
            row = self.conn.execute("SELECT epoch, original_path FROM files WHERE sha256 = ?", (sha,)).fetchone()
            if row is not None:
                raise DuplicateImportError(f"{p}: this file is already in the campaign (epoch {row['epoch']}, "
                                           f"imported from {row['original_path']}); nothing was changed")
        return shas

    def _import(self, epoch: str, items: Sequence[tuple[Path, str]], *, setup: int | None, validate, frames_of,
                create_epoch: dict | None, placed: list | None = None, shas: list[str] | None = None) -> list[str]:
        """Import coarse and fine files of one epoch in one transaction (see :meth:`import_files`).

        ``placed`` is each file's (set-up, frame JSON) when already worked out (:func:`setup_tables.place_files`),
        ``shas`` their checksums when already checked (:meth:`_checked_new`): each file is hashed once.
        """
        if shas is None:
            shas = self._checked_new(items)
        if placed is None:
            existing = [] if create_epoch is not None else self.files(epoch, setup=None)
            placed = setup_tables.place_files(epoch, items, existing, setup=setup, frames_of=frames_of,
                                              validate=validate)
        ensure_free(self.folder / SCANS_DIR, sum(p.stat().st_size for p, _ in items) + MB)
        ep = create_epoch if create_epoch is not None else dict(self.epoch(epoch).to_dict())
        copied: list[Copied] = []
        marks: list[int] = []
        try:
            # each copy journaled at once: a kill leaves none unknown
            for (p, role), (k, frame), sha in zip(items, placed, shas, strict=True):
                got = copy_in(self.folder, p, SCANS_DIR, sha256=sha)
                copied.append(got)
                marks.append(self._journal(got, p, {"kind": "scan", "epoch": epoch, "role": role, "setup": k,
                                                    "frame": frame, "epoch_datetime": ep["datetime"],
                                                    "epoch_notes": ep.get("notes", ""),
                                                    "header": _header_or_none(self.folder / got.rel)}))
            with self.transaction() as c:
                if create_epoch is not None:
                    c.execute("INSERT INTO epochs(label, datetime, notes, created) VALUES (?, ?, ?, ?)",
                              (create_epoch["label"], create_epoch["datetime"], create_epoch.get("notes", ""),
                               now_iso()))
                    digests.seal_row(c, "epochs", create_epoch["label"])
                for (p, role), got, (k, frame) in zip(items, copied, placed, strict=False):
                    c.execute("INSERT INTO files(sha256, epoch, role, stored_path, original_path, size, imported, "
                              "setup, frame) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                              (got.sha256, epoch, role, got.rel, str(p.resolve()), got.size, now_iso(), k, frame))
                for role in dict.fromkeys(r for _, r in items):
                    these = [(p, sha, k) for (p, r), sha, (k, _) in zip(items, shas, placed, strict=False) if r == role]
                    self.log_action(c, "import", epoch, {"role": role, "files": [str(p) for p, _, _ in these],
                                                         "sha256": [sha for _, sha, _ in these],
                                                         **({"setups": sorted({k for _, _, k in these})}
                                                            if any(k != 1 for _, _, k in these) else {})})
        except BaseException:
            self._undo_import(copied, marks)
            raise
        self._link_by_visit(epoch, [(got.rel, role, k, p.name) for (p, role), got, (k, _) in
                                    zip(items, copied, placed, strict=True)])
        return shas

    def _link_by_visit(self, epoch: str, stored: Sequence[tuple[str, str, int, str]]) -> None:
        """Link the scans just stored under the names the surveyor gave them, per visit.

        ``stored``: each file's stored path, role, set-up and original name (see
        :data:`projects.store.imports.BY_VISIT`; a file system without symbolic links is said in the log).
        """
        for rel, role, setup, name in stored:
            link_by_visit(self.folder, rel, epoch, visit_link_name(role, setup, name))

    def add_epoch(self, label: str, when: str, coarse: str | os.PathLike, fines: Sequence = (), *, notes: str = "",
                  validate=None, allow_date: bool = False, frames_of=None) -> str:
        """Create an epoch with its coarse scan (and fine scans), all checked before anything changes.

        A date more than :data:`projects.store.inputs.DATE_SPAN_YEARS` years from the campaign's other
        epochs (for the first one: outside the plausible years) is refused unless ``allow_date``. An
        epoch dated before every measured one never becomes the baseline: the implicit baseline (the
        first measured epoch) is fixed first (see :meth:`baseline_note`). The coarse scan is set-up 1
        (a coarse file of several scan positions: set-ups 1, 2...); ``frames_of`` as in :meth:`import_files`.
        """
        if not label or not label.strip() or any(ch in label for ch in "/\\\n"):
            raise InputError(f"epoch label {label!r} is not usable (no slashes or line breaks)")
        when = parse_datetime(when)
        if self.conn.execute("SELECT 1 FROM epochs WHERE label = ?", (label,)).fetchone():
            raise InputError(f"epoch {label!r} already exists; use another --label or add-fine to add files to it")
        inputs.check_computable(when)
        if not allow_date:
            inputs.check_epoch_date(when, [e.datetime for e in self.epochs()])
        items = [(Path(coarse), "coarse")] + [(Path(f), "fine") for f in fines]
        shas = self._checked_new(items)
        placed = setup_tables.place_files(label, items, [], setup=1, frames_of=frames_of, validate=validate)
        self._pin_baseline_before(when)  # after every file was read: a refused file changes nothing
        self._import(label, items, setup=1, validate=validate, frames_of=frames_of,
                     create_epoch={"label": label, "datetime": when, "notes": notes}, placed=placed, shas=shas)
        return label

    def add_setup(self, label: str, coarse: str | os.PathLike, fines: Sequence = (), *, validate=None,
                  frames_of=None) -> list[int]:
        """Add a set-up (another station of the same visit) to an epoch: its coarse scan and fine scans.

        Returns the new set-up's number (several, for a coarse file of several scan positions). All is
        checked before anything changes; ``frames_of`` as in :meth:`import_files`.
        """
        self.epoch(label)
        new = self.setups(label)[-1] + 1
        items = [(Path(coarse), "coarse")] + [(Path(f), "fine") for f in fines]
        self._import(label, items, setup=new, validate=validate, frames_of=frames_of, create_epoch=None)
        return [k for k in self.setups(label) if k >= new]

    def _pin_baseline_before(self, when: str) -> None:
        """Fix the implicit baseline (the first measured epoch) before an epoch dated earlier arrives."""
        if self.settings().get("baseline"):
            return
        measured = [e for e in self.epochs() if (r := self.result(e.label)) is not None and r.stage == "measured"]
        if measured and when < measured[0].datetime:
            self.set_setting("baseline", measured[0].label)

    def baseline_note(self, label: str) -> str | None:
        """A line for the user when epoch ``label`` is dated before the campaign's baseline, else None."""
        base = self.settings().get("baseline")
        if not base or base == label:
            return None
        ep, b = self.epoch(label), self.epoch(base)
        if ep.datetime >= b.datetime:
            return None
        return (f"epoch {label} is dated before the baseline {base}: it is measured against {base} with a negative "
                f"time; the baseline changes only with 'bridgesurvey settings DIR baseline {label}'")

    # ------------------------------------------------------------------ results
    def save_plan(self, epoch: str, plan_json: dict, inputs_hash: str, preview: tuple[bytes, str] | None = None,
                  *, setup: int = 1) -> None:
        """Store an epoch's (set-up's) plan (and the encoded map preview it came from), dropping its old centroids."""
        if setup != 1:
            with self.transaction() as c:
                setup_tables.write_plan(c, epoch, setup, plan_json, inputs_hash, now_iso(), preview)
                for table in ("setup_plans", "setup_results") + (("setup_previews",) if preview is not None else ()):
                    digests.seal(c, table, (epoch, setup))
                self.log_action(c, "plan", epoch, {"inputs_hash": inputs_hash, "setup": setup})
            return
        with self.transaction() as c:
            c.execute("INSERT OR REPLACE INTO plans(epoch, json, inputs_hash, created) VALUES (?, ?, ?, ?)",
                      (epoch, json.dumps(plan_json), inputs_hash, now_iso()))
            if preview is not None:
                c.execute("INSERT OR REPLACE INTO map_previews(epoch, inputs_hash, arrays, annotations) "
                          "VALUES (?, ?, ?, ?)", (epoch, inputs_hash, preview[0], preview[1]))
            c.execute("INSERT OR REPLACE INTO epoch_results(epoch, stage, inputs_hash, processed) VALUES (?, ?, ?, ?)",
                      (epoch, "planned", inputs_hash, now_iso()))
            c.execute("DELETE FROM centroids WHERE epoch = ?", (epoch,))
            digests.seal(c, "plans", (epoch,))
            if preview is not None:
                digests.seal(c, "map_previews", (epoch,))
            digests.seal(c, "epoch_results", (epoch,))
            self.log_action(c, "plan", epoch, {"inputs_hash": inputs_hash})

    def stored_plan(self, epoch: str, setup: int = 1) -> StoredPlan | None:
        """An epoch's (set-up's) plan with the inputs hash it was made from, or None when it has none."""
        if setup != 1:
            row = self.conn.execute("SELECT json, inputs_hash, created FROM setup_plans WHERE epoch = ? AND setup = ?",
                                    (epoch, setup)).fetchone()
            if row is None or not self._setup_plan_sound(epoch, setup):
                return None
        else:
            row = self.conn.execute("SELECT json, inputs_hash, created FROM plans WHERE epoch = ?", (epoch,)).fetchone()
        if row is None or (setup == 1 and not self._plan_sound(epoch)):
            return None  # a damaged plan is stale: planned again
        doc = json.loads(row["json"])
        return StoredPlan(epoch, ScanPlan.from_json(doc), doc, row["inputs_hash"], row["created"])

    # -- a stored result whose digest does not match (projects.store.digests) is served as absent: stale
    def is_sound(self, table: str, key: Sequence) -> bool:
        """Whether a stored group of ``table`` still matches its digest (cached until this connection writes)."""
        cache = self._sound_cache()
        k = (table, tuple(key))
        if k not in cache:
            cache[k] = digests.is_sound(self.conn, table, key)
        return cache[k]

    def _sound_cache(self) -> dict[tuple, bool]:
        """(table, key) -> whether the group matches its digest, emptied whenever this connection has written."""
        changes = self.conn.total_changes
        if changes != self._sound_at:
            self._sound.clear()
            self._sound_at = changes
        return self._sound

    def damaged_results(self, *, pictures: bool = True) -> list[tuple[str, tuple]]:
        """(table, key) of every stored result group that fails its digest (see :mod:`projects.store.digests`).

        Each table is checked in one pass a query (:func:`digests.sound_groups`; one group at a time that is a few
        queries a visit, thousands at 520 visits), and what it found is what :meth:`is_sound` then answers.
        ``pictures=False`` leaves out the map previews (:data:`digests.PICTURES`): pictures of a few hundred kB a
        visit, nine tenths of a long campaign's stored bytes, which no number is computed from. Each is checked
        where it is shown (:meth:`map_preview`), by ``verify`` and by ``process`` (:meth:`preview_to_remake`).
        """
        cache = self._sound_cache()
        out = []
        for table in digests.GROUPS:
            if pictures or table not in digests.PICTURES:
                for key, ok in digests.sound_groups(self.conn, table).items():
                    cache[(table, key)] = ok
                    if not ok:
                        out.append((table, key))
        return out

    def _exists(self, table: str, epoch: str) -> bool:
        return self.conn.execute(f"SELECT 1 FROM {table} WHERE epoch = ?", (epoch,)).fetchone() is not None

    def _plan_sound(self, epoch: str) -> bool:
        """The plan matches its digest (its map preview, a picture, does not decide: :meth:`preview_to_remake`)."""
        return not self._exists("plans", epoch) or self.is_sound("plans", (epoch,))

    def _stage1_sound(self, epoch: str) -> bool:
        return self.is_sound("epoch_results", (epoch,)) and self._plan_sound(epoch)

    def _setup_plan_sound(self, epoch: str, setup: int) -> bool:
        """A further set-up's plan matches its digest (as :meth:`_plan_sound` for set-up 1)."""
        key = (epoch, setup)
        present = self.conn.execute("SELECT 1 FROM setup_plans WHERE epoch = ? AND setup = ?", key).fetchone()
        return present is None or self.is_sound("setup_plans", key)

    def preview_to_remake(self, epoch: str, setup: int = 1) -> bool:
        """Whether an epoch's (set-up's) stored map preview fails its digest and planning again would remake it.

        A damaged preview is never shown (:meth:`map_preview`). ``process`` plans an unedited plan again, which
        remakes its preview from the coarse scan; an edited plan is kept (planning again would lose the edits),
        and its preview stays unshown. Reading a preview costs a few hundred kB a visit: the quick looks
        (``status``, the application's tree) leave them to ``verify`` and ``process``.
        """
        key: tuple = (epoch,) if setup == 1 else (epoch, setup)
        table, plans = ("map_previews", "plans") if setup == 1 else ("setup_previews", "setup_plans")
        where = " AND ".join(f"{k} = ?" for k in ("epoch", "setup")[:len(key)])
        if self.conn.execute(f"SELECT 1 FROM {table} WHERE {where}", key).fetchone() is None \
                or self.is_sound(table, key):
            return False
        row = self.conn.execute(f"SELECT json FROM {plans} WHERE {where}", key).fetchone()
        return row is not None and not json.loads(row[0]).get("edited")

    def _setup_result_row(self, epoch: str, setup: int):
        """A further set-up's sound result row, or None (absent, or failing its digest or its plan's)."""
        row = setup_tables.read_result(self.conn, epoch, setup)
        if row is None or not self.is_sound("setup_results", (epoch, setup)) or not self._setup_plan_sound(epoch, setup):
            return None
        return row

    def damaged_displacements(self) -> list[str]:
        """The epochs whose stored displacements fail their digest (left out of every table: say so)."""
        return [key[0] for key in digests.keys_of(self.conn, "displacement_sets")
                if not self.is_sound("displacement_sets", key)]

    def _displacements_sound(self, epoch: str) -> bool:
        return self.is_sound("displacement_sets", (epoch,))

    def plan(self, epoch: str, setup: int = 1):
        """An epoch's (set-up's) :class:`lidar.plan.ScanPlan`, or None when it has none."""
        stored = self.stored_plan(epoch, setup)
        return None if stored is None else stored.plan

    def map_preview(self, epoch: str, setup: int = 1):
        """The stored :class:`projects.map_previews.MapPreview` of an epoch (set-up), or None."""
        if setup != 1:
            row = self.conn.execute("SELECT arrays, annotations FROM setup_previews WHERE epoch = ? AND setup = ?",
                                    (epoch, setup)).fetchone()
            sound = row is not None and self.is_sound("setup_previews", (epoch, setup))
        else:
            row = self.conn.execute("SELECT arrays, annotations FROM map_previews WHERE epoch = ?", (epoch,)).fetchone()
            sound = row is not None and self.is_sound("map_previews", (epoch,))
        if not sound:
            return None
        # local: the previews' lidar.detection (scikit-image): 0.08-0.1 s of reflector list's start-up (measured)
        from projects.store.previews import decode_preview

        try:
            return decode_preview(row[0], row[1])
        except CampaignError:
            raise
        except Exception:  # undecodable despite its digest: not shown, never a crash
            return None

    def result(self, epoch: str, setup: int = 1) -> EpochResult | None:
        """How far processing has taken an epoch (set-up), or None when it has not started (or its results are damaged)."""
        if setup != 1:
            got = self._setup_result_row(epoch, setup)
            return None if got is None else EpochResult(epoch, got["stage"], got["inputs_hash"], got["processed"])
        row = self.conn.execute("SELECT epoch, stage, inputs_hash, processed FROM epoch_results WHERE epoch = ?",
                                (epoch,)).fetchone()
        if row is None or not self._stage1_sound(epoch):
            return None
        return EpochResult(**dict(row))

    def save_centroids(self, epoch: str, cents: dict, inputs_hash: str, params: dict, *,
                       closures: dict | None = None, time_source: str = "points", setup: int = 1) -> None:
        """Store an epoch's (set-up's) centroids (and its closure centroids) as its measured stage-1 result."""
        if setup != 1:
            with self.transaction() as c:
                setup_tables.write_centroids(c, epoch, setup, cents, closures or {}, inputs_hash, now_iso(), time_source)
                digests.seal(c, "setup_results", (epoch, setup))
                self.log_action(c, "measure", epoch, {"inputs_hash": inputs_hash, "params": params, "setup": setup,
                                                     "found": sum(int(t.found) for t in cents.values())})
            return
        with self.transaction() as c:
            c.execute("DELETE FROM centroids WHERE epoch = ?", (epoch,))
            for rid, tc in cents.items():
                xyz = [float(v) if np.isfinite(v) else None for v in tc.xyz_socs]
                c.execute("INSERT INTO centroids(epoch, reflector, found, x, y, z, cov, n, threshold, separability, "
                          "sigma_range_m, flags, n_window) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                          (epoch, rid, int(tc.found), *xyz, json.dumps(np.nan_to_num(tc.cov, nan=0.0).tolist()),
                           int(tc.n_points), _f(tc.threshold), _f(tc.separability), _f(tc.sigma_range_m),
                           json.dumps(list(tc.flags)), int(tc.n_window)))
            field_tables.write_centroid_extras(c, epoch, cents, closures or {}, time_source)
            c.execute("INSERT OR REPLACE INTO epoch_results(epoch, stage, inputs_hash, processed) VALUES (?, ?, ?, ?)",
                      (epoch, "measured", inputs_hash, now_iso()))
            digests.seal(c, "epoch_results", (epoch,))
            self.log_action(c, "measure", epoch, {"inputs_hash": inputs_hash, "params": params,
                                             "found": sum(int(t.found) for t in cents.values())})

    def centroids(self, epoch: str, setup: int = 1) -> dict[str, TargetCentroid]:
        """An epoch's (set-up's) stored centroids by target, with their times, incidences and clipped fractions.

        Empty when they fail their digest (stale: processing measures the epoch again).
        """
        if setup != 1:
            row = self._setup_result_row(epoch, setup)
            return setup_tables.centroids_of(row) if row is not None and row["stage"] == "measured" else {}
        if not self._centroids_sound(epoch):
            return {}
        extras = field_tables.read_centroid_extras(self.conn, epoch)
        out = {}
        for r in self.conn.execute("SELECT * FROM centroids WHERE epoch = ? ORDER BY reflector", (epoch,)):
            xyz = np.array([np.nan if r[k] is None else r[k] for k in ("x", "y", "z")], dtype=float)
            out[r["reflector"]] = TargetCentroid(
                r["reflector"], xyz, np.array(json.loads(r["cov"]), dtype=float), int(r["n"]),
                _nan(r["threshold"]), _nan(r["separability"]), tuple(json.loads(r["flags"])),
                -1 if r["n_window"] is None else int(r["n_window"]),  # -1: not recorded (schema 1)
                sigma_range_m=_nan(r["sigma_range_m"]))
            out[r["reflector"]] = field_tables.with_extra(out[r["reflector"]], extras.get(r["reflector"]))
        return out

    def _centroids_sound(self, epoch: str) -> bool:
        """Set-up 1's stored centroids of an epoch match their digest (or there are none to check)."""
        return not self._exists("epoch_results", epoch) or self.is_sound("epoch_results", (epoch,))

    def centroid_flags(self, epoch: str, setup: int = 1) -> dict[str, tuple[str, ...]]:
        """An epoch's (set-up's) stored centroids' flags by target, as :meth:`centroids` gives them (its flags only).

        What an epoch's state needs (a centroid is found unless flagged ``not_found``), without reading each
        centroid's covariance and extras: ``status`` and the application's tree ask it for every visit.
        """
        if setup != 1:
            return {rid: t.flags for rid, t in self.centroids(epoch, setup).items()}
        if not self._centroids_sound(epoch):
            return {}
        return {r["reflector"]: tuple(json.loads(r["flags"])) for r in
                self.conn.execute("SELECT reflector, flags FROM centroids WHERE epoch = ? ORDER BY reflector", (epoch,))}

    def closure_centroids(self, epoch: str, setup: int = 1) -> dict[str, TargetCentroid]:
        """The epoch's (set-up's) closure centroids: targets its plan scanned again at the end of the visit."""
        if setup != 1:
            return setup_tables.centroids_of(self._setup_result_row(epoch, setup), "closures")
        return field_tables.read_closures(self.conn, epoch)

    def time_source(self, epoch: str, setup: int = 1) -> str | None:
        """Where the epoch's (set-up's) centroid times come from: ``points``, ``plan`` or None (not measured)."""
        if setup != 1:
            row = self._setup_result_row(epoch, setup)
            return None if row is None or row["stage"] != "measured" else row["time_source"]
        extras = field_tables.read_centroid_extras(self.conn, epoch)
        return next((e.get("time_source") for e in extras.values()), None)

    def field_model(self) -> tuple[FieldModel, str] | None:
        """The campaign's stored field model and its digest, or None before processing fitted one."""
        got = field_tables.read_field_model(self.conn)
        return None if got is None else (FieldModel.from_json(got[0]), got[1])

    def save_stage2(self, baseline: str, model: FieldModel | None, epochs: Sequence, *,
                    revisions: Sequence[dict] = ()) -> None:
        """Store what stage 2 computed, in one transaction: the field model when it changed, each epoch's displacements.

        ``epochs`` are :class:`lidar.stage2.EpochDisplacementResult` (label, displacements, inputs hash,
        systematics); ``revisions`` (:meth:`lidar.stage2.Revision.to_json`) the stored values they changed,
        logged as one ``revisions`` entry (:meth:`last_revisions`). The campaign's ``bias.json`` (the model as
        a file, for other tools) is written after the commit, atomically.
        """
        with self.transaction() as c:
            if model is not None:
                field_tables.write_field_model(c, model.to_json(), model.digest(), now_iso())
            for e in epochs:
                self._write_displacements(c, e.label, baseline, e.displacements, e.inputs_hash, e.systematics)
            if revisions:
                self.log_action(c, "revisions", None, {"revised": list(revisions)})
        if model is not None:
            write_atomic(self.folder / BIAS_FILE, json.dumps(model.to_json(), indent=1) + "\n")

    def systematics(self, epoch: str) -> dict:
        """The scale and drift an epoch's displacements were computed with (empty before)."""
        return field_tables.read_set_extras(self.conn, epoch)

    def save_displacements(self, epoch: str, baseline: str, res, inputs_hash: str, *,
                           systematics: dict | None = None) -> None:
        """Store an epoch's displacements, their budgets and the systematics they were corrected for."""
        with self.transaction() as c:
            self._write_displacements(c, epoch, baseline, res, inputs_hash, systematics)

    def _write_displacements(self, c: sqlite3.Connection, epoch: str, baseline: str, res, inputs_hash: str,
                             systematics: dict | None) -> None:
        c.execute("DELETE FROM displacement_sets WHERE epoch = ?", (epoch,))
        c.execute("INSERT INTO displacement_sets(epoch, baseline, inputs_hash, normal, reference_point, "
                  "reference_ids, normal_mode, flags, processed) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                  (epoch, baseline, inputs_hash, json.dumps(np.asarray(res.normal_socs).tolist()),
                   json.dumps(np.asarray(res.reference_point_socs).tolist()), json.dumps(list(res.reference_ids)),
                   res.normal_mode, json.dumps(list(res.flags)), now_iso()))
        for d in res.displacements:
            c.execute("INSERT INTO displacements(epoch, reflector, displacement_m, sigma_m, vertical_m, "
                      "baseline_vertical_m, flags) VALUES (?, ?, ?, ?, ?, ?, ?)",
                      (epoch, d.reflector, _f(d.displacement_m), _f(d.sigma_m), _f(d.vertical_m),
                       _f(d.baseline_vertical_m), json.dumps(list(d.flags))))
        for rc in res.reference_checks:
            c.execute("INSERT INTO reference_checks(epoch, reflector, median_change_m, max_change_m, moved, "
                      "missing, suspect) VALUES (?, ?, ?, ?, ?, ?, ?)",
                      (epoch, rc.reflector, _f(rc.median_change_m), _f(rc.max_change_m), int(rc.moved),
                       int(rc.missing), int(rc.suspect)))
        field_tables.write_displacement_extras(c, epoch, res, systematics)
        digests.seal(c, "displacement_sets", (epoch,))
        self.log_action(c, "displacements", epoch, {"baseline": baseline, "inputs_hash": inputs_hash})

    def displacement_set(self, epoch: str) -> DisplacementSet | None:
        """What an epoch's displacements were computed with, or None before they are."""
        r = self.conn.execute("SELECT * FROM displacement_sets WHERE epoch = ?", (epoch,)).fetchone()
        if r is None or not self._displacements_sound(epoch):
            return None  # damaged: stale, computed again by 'process'
        return DisplacementSet(r["epoch"], r["baseline"], r["inputs_hash"], np.array(json.loads(r["normal"]), float),
                               np.array(json.loads(r["reference_point"]), float), tuple(json.loads(r["reference_ids"])),
                               r["normal_mode"], tuple(json.loads(r["flags"])), r["processed"])

    def displacements(self) -> list[DisplacementRecord]:
        """Every stored displacement, by epoch date then target (see :func:`projects.history.histories`).

        Read once until the campaign changes (any connection's write): ``status`` needs them for the epochs'
        states and for the table of values, the report and the application more often.
        """
        when = (self.conn.total_changes, self.conn.execute("PRAGMA data_version").fetchone()[0])
        if self._records is None or self._records[0] != when:
            self._records = (when, self._displacement_records())
        return list(self._records[1])

    def _displacement_records(self, where: str = "", args: tuple = (), *, newest_first: bool = False,
                              limit: int | None = None) -> list[DisplacementRecord]:
        """Displacement records, optionally narrowed by ``where``.

        ``where`` is SQL over ``d`` displacements and ``e`` epochs, with ``args``: the store's own
        queries only, never a caller's text.
        """
        order = "DESC" if newest_first else "ASC"
        q = f"""SELECT e.label AS epoch, e.datetime AS datetime, d.reflector, d.displacement_m, d.sigma_m,
                      d.flags AS flags, s.flags AS epoch_flags, s.baseline, x.extra AS extra, sx.extra AS set_extra
               FROM displacements d JOIN displacement_sets s ON s.epoch = d.epoch
               JOIN epochs e ON e.label = d.epoch
               LEFT JOIN displacement_extras x ON x.epoch = d.epoch AND x.reflector = d.reflector
               LEFT JOIN displacement_set_extras sx ON sx.epoch = d.epoch {'WHERE ' + where if where else ''}
               ORDER BY e.datetime {order}, e.label {order}, d.reflector"""
        sound: dict[str, bool] = {}
        out = []
        flag_lists: dict[str, tuple[str, ...]] = {}  # a flags text decoded once (most are "[]", or their epoch's)
        epoch_extra: dict[str, Mapping] = {}  # the epoch's systematics, decoded once and shared by its records

        def flags(text: str) -> tuple[str, ...]:
            if text not in flag_lists:
                flag_lists[text] = tuple(json.loads(text))
            return flag_lists[text]

        self.epochs()  # their dates are served with the values: a damaged epoch row is named, never served
        for r in self.conn.execute(q, args).fetchall():
            ep = r["epoch"]
            if ep not in sound:
                sound[ep] = self._displacements_sound(ep)
                epoch_extra[ep] = json.loads(r["set_extra"]) if r["set_extra"] else {}
            if sound[ep]:  # a damaged epoch's values are never served
                out.append(DisplacementRecord(ep, r["datetime"], r["reflector"], r["displacement_m"], r["sigma_m"],
                                              flags(r["flags"]), flags(r["epoch_flags"]), r["baseline"],
                                              json.loads(r["extra"]) if r["extra"] else {}, epoch_extra[ep]))
                if limit and len(out) >= limit:
                    break
        return out

    def last_displacement(self, reflector: str, *, at_or_before: str) -> DisplacementRecord | None:
        """A target's latest displacement with a value, in an epoch dated no later than epoch ``at_or_before``."""
        rows = self._displacement_records("d.reflector = ? AND d.displacement_m IS NOT NULL AND e.datetime <= "
                                          "(SELECT datetime FROM epochs WHERE label = ?)", (reflector, at_or_before),
                                          newest_first=True, limit=1)
        return rows[0] if rows else None

    def displacement_flags(self, epoch: str) -> list[str]:
        """Every per-target displacement flag of an epoch (one entry per target and flag)."""
        if not self._displacements_sound(epoch):
            return []
        rows = self.conn.execute("SELECT flags FROM displacements WHERE epoch = ?", (epoch,)).fetchall()
        return [f for r in rows for f in json.loads(r[0])]

    def reference_checks(self, epoch: str) -> list[ReferenceCheck]:
        """How each pier target moved in an epoch."""
        if not self._displacements_sound(epoch):
            return []
        return [ReferenceCheck(r["epoch"], r["reflector"], r["median_change_m"], r["max_change_m"], bool(r["moved"]),
                               bool(r["missing"]), bool(r["suspect"]))
                for r in self.conn.execute("SELECT * FROM reference_checks WHERE epoch = ?", (epoch,))]

    # ------------------------------------------------------------------ limits
    def set_limit(self, reflector: str, rule: str) -> None:

        lim = parse_rule(rule, self.span_m)
        if reflector != "*":
            self.reflector(reflector)
        with self.transaction() as c:
            c.execute("INSERT OR REPLACE INTO limits(reflector, warning_mm, alarm_mm, rule) VALUES (?, ?, ?, ?)",
                      (reflector, lim.warning_mm, lim.alarm_mm, rule))
            digests.seal_row(c, "limits", reflector)
            self.log_action(c, "limit", None, {"reflector": reflector, "rule": rule})

    def limit_for(self, reflector: str):
        row = self.conn.execute("SELECT * FROM limits WHERE reflector = ?", (reflector,)).fetchone() or \
            self.conn.execute("SELECT * FROM limits WHERE reflector = '*'").fetchone()
        if row is not None:
            self._check_row("limits", row)
        return None if row is None else Limit(row["warning_mm"], row["alarm_mm"], row["rule"])

    def limits(self) -> list[LimitRecord]:
        """Every limit set, by target ("*" is the default for all measurement targets)."""
        rows = self.conn.execute("SELECT * FROM limits ORDER BY reflector").fetchall()
        for r in rows:
            self._check_row("limits", r)
        return [LimitRecord(r["reflector"], Limit(r["warning_mm"], r["alarm_mm"], r["rule"])) for r in rows]

    def integrity_check(self) -> str:
        res = self.conn.execute("PRAGMA integrity_check").fetchone()[0]
        fk = self.conn.execute("PRAGMA foreign_key_check").fetchall()
        return res if not fk else f"foreign key violations: {len(fk)}"


def _profile_of(settings: dict, label: str | None, setup: int, campaign: ScannerProfile) -> ScannerProfile:
    """A set-up's scanner from the settings: its own, else its epoch's, else the campaign's."""
    own = settings.get("setup_scanners", {}).get(label, {}).get(str(setup)) if label and setup != 1 else None
    if own:
        return ScannerProfile.from_dict(own, source=f"epoch {label} set-up {setup} scanner")
    own = settings.get("epoch_scanners", {}).get(label) if label else None
    return ScannerProfile.from_dict(own, source=f"epoch {label} scanner") if own else campaign


def _layout_of(reflectors: Sequence[Reflector], at: str | None) -> Layout:
    """The layout of the reflectors expected at the ISO date-time ``at`` (all active ones when None)."""
    rows = [r for r in reflectors if r.expected_at(at)]
    return Layout(tuple(r.id for r in rows), tuple(r.group for r in rows),
                  np.array([r.xyz_layout for r in rows], dtype=float).reshape(-1, 3),
                  np.array([r.diameter_m for r in rows], dtype=float),
                  np.array([r.normal_layout for r in rows], dtype=float).reshape(-1, 3))


def _header_or_none(path: Path) -> dict | None:

    try:
        return header_facts(path)
    except SurveyError:
        return None


#: What to do about a damaged input row, by its table (see :data:`projects.store.digests.INPUTS`).
INPUT_REMEDY = {
    "meta": "restore campaign.sqlite from a backup",
    "reflectors": "restore campaign.sqlite from a backup",
    "epochs": "run 'bridgesurvey repair DIR' (it takes the epoch's date and notes again from the journal of imports) "
              "or restore campaign.sqlite from a backup",
    "limits": "run 'bridgesurvey repair DIR' (it takes the rule again from the campaign's log) or set it again with "
              "'bridgesurvey limit DIR --reflector 'REFLECTOR' --rule RULE'",
    "field_models": "run 'bridgesurvey process' to fit it again",
}


def describe_input(table: str, key) -> str:
    """An input row for a message ("limit of every measurement target", "epoch 2026-03-09", ...)."""
    if table == "meta":
        return {"scanner_profile": "the campaign's scanner profile",
                "settings": "the campaign's settings record (processing parameters, baseline, each epoch's scanner)",
                }.get(key, f"the campaign's {str(key).replace('_', ' ')}")
    if table == "limits":
        return "the limit of every measurement target (*)" if key == "*" else f"the limit of target {key}"
    if table == "field_models":
        return "the field model"
    return f"{digests.INPUTS[table].name} {key}"


def damaged_input_line(folder: Path, table: str, key) -> str:
    """The one line naming a damaged input row and what to do (the same for every command and ``verify``)."""
    remedy = INPUT_REMEDY[table].replace("DIR", str(folder)).replace("REFLECTOR", str(key))
    what = describe_input(table, key)
    return (f"{folder}: {what} is damaged in campaign.sqlite (its values do not match the checksum stored with "
            f"them), so it is not used; {remedy}")


def _epoch(r: sqlite3.Row) -> Epoch:
    return Epoch(r["label"], r["datetime"], r["notes"], r["created"])


def _reflector(r: sqlite3.Row) -> Reflector:
    return Reflector(r["id"], r["grp"], (r["x"], r["y"], r["z"]), r["diameter_m"],
                     (_nan(r["nx"]), _nan(r["ny"]), _nan(r["nz"])), r["installed"], r["retired"], r["replaces"],
                     r["note"])


def _f(v) -> float | None:
    return float(v) if v is not None and np.isfinite(v) else None


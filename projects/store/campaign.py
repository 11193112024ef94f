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
import fcntl
import hashlib
import json
import os
import sqlite3
import uuid
from pathlib import Path
from typing import Iterable, Optional, Sequence

import numpy as np

from lidar.centroid import TargetCentroid
from lidar.layout import Layout, check_layout
from lidar.scanner_profile import ScannerProfile
from projects.store import schema
from projects.store.errors import CampaignError, CampaignLockedError, DuplicateImportError, InputError
from projects.store.series import SeriesTables
from projects.store.records import (DisplacementRecord, DisplacementSet, Epoch, EpochResult, LimitRecord, LogEntry,
                              Reflector, ReferenceCheck, ScanFile, StoredPlan)

DB_NAME = "campaign.sqlite"
SCANS_DIR = "scans"
CAMERA_DIR = "camera"
ENV_DIR = "environment"
PREDICTION_DIR = "prediction"
LOCK_NAME = ".lock"


def now_iso() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return dt.datetime.now(dt.timezone.utc).replace(microsecond=0).isoformat()


def parse_datetime(text: str) -> str:
    """Normalise an ISO 8601 date or date-time; naive values are taken as UTC."""
    try:
        value = dt.datetime.fromisoformat(str(text).strip().replace("Z", "+00:00"))
    except ValueError as exc:
        if "isoformat" not in str(exc):  # ISO 8601 in form, but no such day or time (2027-02-30, 24:30)
            raise InputError(f"date {text!r} is an impossible date: {exc}") from None
        raise InputError(f"date {text!r} is not ISO 8601 (e.g. 2026-03-14 or 2026-03-14T09:30)") from None
    if value.tzinfo is None:
        value = value.replace(tzinfo=dt.timezone.utc)
    return value.isoformat()


def sha256_of(path: Path, chunk: int = 8 << 20) -> str:
    """The SHA-256 of a file (hex), read in chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def _normal_values(n) -> tuple:
    """A layout normal as three SQL values (NULLs when unknown)."""
    return tuple(float(v) for v in n) if np.all(np.isfinite(n)) else (None, None, None)


def _nan(v) -> float:
    return float("nan") if v is None else float(v)


class Campaign(SeriesTables):
    """An open campaign. Use :meth:`create` or :meth:`open`, preferably as a context manager."""

    def __init__(self, folder: Path, conn: sqlite3.Connection, lock_fh, *, writable: bool):
        self.folder = folder
        self.conn = conn
        self._lock_fh = lock_fh
        self.writable = writable

    # ------------------------------------------------------------------ opening
    @classmethod
    def create(cls, folder: str | os.PathLike, *, name: str, layout: Layout, span_m: Optional[float] = None,
               profile: Optional[ScannerProfile] = None) -> "Campaign":
        """Create a new campaign folder (which must not hold a campaign yet).

        ``profile`` is the scanner (default: the catalogue's Riegl VZ-1000, the dissertation's).
        """
        if profile is None:
            from lidar.scanner_catalogue import DEFAULT_SCANNER, get_scanner

            profile = get_scanner(DEFAULT_SCANNER)
        folder = Path(folder)
        if not name.strip():
            raise InputError("the campaign needs a name (--name)")
        if span_m is not None and not (np.isfinite(span_m) and span_m > 0):
            raise InputError(f"span length must be positive, got {span_m}")
        check_layout(layout)
        if (folder / DB_NAME).exists():
            raise CampaignError(f"{folder}: already holds a campaign; open it instead of creating one")
        if folder.exists() and not folder.is_dir():
            raise CampaignError(f"{folder}: exists and is not a folder")
        folder.mkdir(parents=True, exist_ok=True)
        (folder / SCANS_DIR).mkdir(exist_ok=True)
        tmp = folder / f".{DB_NAME}.{uuid.uuid4().hex}.part"
        conn = sqlite3.connect(tmp)
        try:
            with conn:
                schema.create(conn)
                meta = {"name": name.strip(), "span_m": "" if span_m is None else repr(float(span_m)),
                        "scanner_profile": json.dumps(profile.to_dict()), "created": now_iso(),
                        "settings": json.dumps({})}
                conn.executemany("INSERT INTO meta(key, value) VALUES (?, ?)", meta.items())
                conn.executemany(
                    "INSERT INTO reflectors(id, grp, x, y, z, diameter_m, nx, ny, nz) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    [(i, g, *map(float, p), float(d), *_normal_values(n)) for i, g, p, d, n in
                     zip(layout.ids, layout.groups, layout.xyz, layout.diameters_m, layout.normals)])
                conn.execute("INSERT INTO log(time, action, epoch, details) VALUES (?, 'init', NULL, ?)",
                             (now_iso(), json.dumps({"name": name, "reflectors": len(layout)})))
        finally:
            conn.close()
        os.replace(tmp, folder / DB_NAME)
        return cls.open(folder)

    @classmethod
    def open(cls, folder: str | os.PathLike, *, writable: bool = True) -> "Campaign":
        """Open a campaign; a writer holds an exclusive lock, readers a shared one."""
        folder = Path(folder)
        db = folder / DB_NAME
        if not db.is_file():
            raise CampaignError(f"{folder}: no campaign here (no {DB_NAME}); create one with 'bridgesurvey init'")
        lock_fh = open(folder / LOCK_NAME, "a+")
        try:
            fcntl.flock(lock_fh, (fcntl.LOCK_EX if writable else fcntl.LOCK_SH) | fcntl.LOCK_NB)
        except BlockingIOError:
            lock_fh.seek(0)
            holder = lock_fh.read().strip() or "another process"
            lock_fh.close()
            raise CampaignLockedError(f"{folder}: the campaign is in use by {holder}; wait for it to finish "
                                      "and try again") from None
        if writable:
            lock_fh.seek(0)
            lock_fh.truncate()
            lock_fh.write(f"BridgeSurvey process {os.getpid()}")
            lock_fh.flush()
        try:
            conn = sqlite3.connect(db, timeout=30)
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA foreign_keys = ON")
            conn.execute("PRAGMA journal_mode = WAL")
            conn.execute("PRAGMA synchronous = FULL")
            version = schema.version_of(conn)
        except sqlite3.DatabaseError as exc:
            lock_fh.close()
            raise CampaignError(f"{db}: not a readable campaign database ({exc})") from None
        if version > schema.SCHEMA_VERSION:
            conn.close()
            lock_fh.close()
            raise CampaignError(f"{folder}: written by a newer BridgeSurvey (schema {version}, this one reads up to "
                                f"{schema.SCHEMA_VERSION}); update BridgeSurvey")
        if version < schema.SCHEMA_VERSION:
            try:
                if not writable:  # upgrade under a brief exclusive lock, then share again
                    fcntl.flock(lock_fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                schema.migrate(conn, version)
                if not writable:
                    fcntl.flock(lock_fh, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:
                conn.close()
                lock_fh.close()
                raise CampaignLockedError(f"{folder}: the campaign needs a schema upgrade but another process is "
                                          "using it; try again when it has finished") from None
        camp = cls(folder, conn, lock_fh, writable=writable)
        if writable:
            camp._clean_partial_files()
        return camp

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None  # type: ignore[assignment]  # a closed campaign has no connection
        if self._lock_fh is not None:
            with contextlib.suppress(OSError):
                fcntl.flock(self._lock_fh, fcntl.LOCK_UN)
            self._lock_fh.close()
            self._lock_fh = None

    def __enter__(self) -> "Campaign":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @contextlib.contextmanager
    def transaction(self):
        """One atomic change: everything inside commits together or not at all."""
        if not self.writable:
            raise CampaignError("the campaign is open read-only")
        with self.conn:
            yield self.conn

    def _clean_partial_files(self) -> None:
        """Remove what an interrupted import left: temporary copies and files no row refers to."""
        for sub, table in ((SCANS_DIR, "files"), (CAMERA_DIR, "camera_series"), (ENV_DIR, "env_series"),
                           (PREDICTION_DIR, "predictions")):
            folder = self.folder / sub
            known = {r[0] for r in self.conn.execute(f"SELECT stored_path FROM {table}")}
            for p in folder.iterdir() if folder.is_dir() else ():
                if p.name.startswith(".") or f"{sub}/{p.name}" not in known:
                    with contextlib.suppress(OSError):
                        p.chmod(0o644)
                        p.unlink()
        for p in self.folder.glob(f".{DB_NAME}.*.part"):
            p.unlink()

    # ------------------------------------------------------------------ metadata
    def meta(self, key: str, default: str = "") -> str:
        """One campaign-level value of the ``meta`` table (``default`` when it is not set)."""
        row = self.conn.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return default if row is None else row[0]

    def set_meta(self, key: str, value: str) -> None:
        """Set one campaign-level value (``meta`` table), in its own transaction."""
        with self.transaction() as c:
            c.execute("INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", (key, value))

    @property
    def name(self) -> str:
        return self.meta("name", "")

    @property
    def span_m(self) -> Optional[float]:
        v = self.meta("span_m", "")
        return float(v) if v else None

    @property
    def profile(self) -> ScannerProfile:
        return ScannerProfile.from_dict(json.loads(self.meta("scanner_profile", "{}")))

    def profile_for(self, label: Optional[str]) -> ScannerProfile:
        """The scanner of an epoch: its own when it has one (``add-epoch --scanner``), else the campaign's."""
        own = self.settings().get("epoch_scanners", {}).get(label) if label else None
        return ScannerProfile.from_dict(own, source=f"epoch {label} scanner") if own else self.profile

    def set_profile(self, profile: ScannerProfile, *, epoch: Optional[str] = None) -> None:
        """Set the campaign's scanner, or one epoch's (the epoch must exist)."""
        if epoch is None:
            with self.transaction() as c:
                c.execute("UPDATE meta SET value = ? WHERE key = 'scanner_profile'", (json.dumps(profile.to_dict()),))
                self._log(c, "scanner", None, {"name": profile.name})
            return
        self.epoch(epoch)
        s = self.settings()
        s.setdefault("epoch_scanners", {})[epoch] = profile.to_dict()
        with self.transaction() as c:
            c.execute("UPDATE meta SET value = ? WHERE key = 'settings'", (json.dumps(s),))
            self._log(c, "scanner", epoch, {"name": profile.name})

    def settings(self) -> dict:
        return json.loads(self.meta("settings", "{}"))

    def set_setting(self, key: str, value) -> None:
        s = self.settings()
        s[key] = value
        with self.transaction() as c:
            c.execute("UPDATE meta SET value = ? WHERE key = 'settings'", (json.dumps(s),))
            self._log(c, "setting", None, {key: value})

    def _log(self, conn, action: str, epoch: Optional[str], details: dict) -> None:
        conn.execute("INSERT INTO log(time, action, epoch, details) VALUES (?, ?, ?, ?)",
                     (now_iso(), action, epoch, json.dumps(details, default=str)))

    def log(self) -> list[LogEntry]:
        """The campaign's log, oldest first."""
        return [LogEntry(r["id"], r["time"], r["action"], r["epoch"], json.loads(r["details"]))
                for r in self.conn.execute("SELECT * FROM log ORDER BY id")]

    # ------------------------------------------------------------------ reflectors
    def reflectors(self) -> list[Reflector]:
        """Every reflector, retired ones included: reference targets first, then by id."""
        return [_reflector(r) for r in self.conn.execute("SELECT * FROM reflectors ORDER BY grp DESC, id")]

    def reflector(self, rid: str) -> Reflector:
        row = self.conn.execute("SELECT * FROM reflectors WHERE id = ?", (rid,)).fetchone()
        if row is None:
            known = ", ".join(r.id for r in self.reflectors())
            raise InputError(f"unknown reflector {rid!r}; the campaign has {known}")
        return _reflector(row)

    def layout(self, at: Optional[str] = None) -> Layout:
        """Reflectors expected at a date-time (all active ones when None)."""
        rows = [r for r in self.reflectors() if r.expected_at(at)]
        return Layout(tuple(r.id for r in rows), tuple(r.group for r in rows),
                      np.array([r.xyz_layout for r in rows], dtype=float).reshape(-1, 3),
                      np.array([r.diameter_m for r in rows], dtype=float),
                      np.array([r.normal_layout for r in rows], dtype=float).reshape(-1, 3))

    def add_reflector(self, rid: str, group: str, xyz: Sequence[float], *, diameter_m: float = 0.05,
                      installed: Optional[str] = None, replaces: Optional[str] = None, note: str = "") -> None:
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
            self._log(c, "reflector-add", None, {"id": rid, "group": group, "replaces": replaces})

    def retire_reflector(self, rid: str, when: str) -> None:
        r = self.reflector(rid)
        if r.retired:
            raise InputError(f"reflector {rid!r} was already retired on {r.retired}")
        when = parse_datetime(when)
        with self.transaction() as c:
            c.execute("UPDATE reflectors SET retired = ? WHERE id = ?", (when, rid))
            self._log(c, "reflector-retire", None, {"id": rid, "when": when})

    def replace_reflector(self, old: str, new: str, when: str, *, xyz: Optional[Sequence[float]] = None) -> None:
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
            self._log(c, "reflector-replace", None, {"old": old, "new": new, "when": when})

    # ------------------------------------------------------------------ epochs and files
    def epochs(self) -> list[Epoch]:
        """Every epoch, oldest first."""
        return [Epoch(**dict(r)) for r in self.conn.execute("SELECT * FROM epochs ORDER BY datetime, label")]

    def epoch(self, label: str) -> Epoch:
        """One epoch; an unknown label is an :class:`InputError` naming the epochs there are."""
        row = self.conn.execute("SELECT * FROM epochs WHERE label = ?", (label,)).fetchone()
        if row is None:
            labels = [e.label for e in self.epochs()]
            hint = f"; epochs are {', '.join(labels[-8:])}" if labels else "; the campaign has no epochs yet"
            raise InputError(f"no epoch {label!r} in {self.folder}{hint}")
        return Epoch(**dict(row))

    def files(self, epoch: str, role: Optional[str] = None) -> list[ScanFile]:
        """An epoch's scan files (``role`` ``"coarse"`` or ``"fine"``, or both), in import order."""
        q = "SELECT * FROM files WHERE epoch = ?" + (" AND role = ?" if role else "") + " ORDER BY imported, stored_path"
        return [ScanFile(**dict(r)) for r in self.conn.execute(q, (epoch, role) if role else (epoch,))]

    def path_of(self, file: ScanFile) -> Path:
        """Where a stored scan file is on disk."""
        return self.folder / file.stored_path

    def new_series(self, table: str, path: str | os.PathLike, name: Optional[str], what: str) -> tuple[Path, str]:
        """The file and the name of a series about to be imported into ``table``.

        ``table`` is ``camera_series`` or ``env_series``; the file exists and the name (default: the
        file's stem) is usable and free.
        """
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: no such file; check the path")
        name = (name or path.stem).strip()
        if not name or any(ch in name for ch in "/\\\n"):
            raise InputError(f"series name {name!r} is not usable")
        if self.conn.execute(f"SELECT 1 FROM {table} WHERE name = ?", (name,)).fetchone():
            raise InputError(f"{what} named {name!r} is already in the campaign; give another --name")
        return path, name

    def checksum_if_new(self, table: str, path: Path) -> str:
        """The file's sha256, refusing a file already imported into ``table`` under some series name."""
        sha = sha256_of(path)
        row = self.conn.execute(f"SELECT name, original_path FROM {table} WHERE sha256 = ?", (sha,)).fetchone()
        if row is not None:
            raise DuplicateImportError(f"{path}: this file is already in the campaign as series {row['name']!r} "
                                       f"(from {row['original_path']}); nothing was changed")
        return sha

    def import_file(self, src: Path, sha: str, sub: str, record) -> str:
        """Copy ``src`` into ``sub`` read-only and, in one transaction, ``record(conn, stored_path)``.

        ``sha`` is the file's checksum when it was read. On any failure nothing stays: no row, no copy.
        """
        try:
            sha2, rel, _ = self._copy_in(src, sub)
            if sha2 != sha:
                raise InputError(f"{src}: the file changed while it was being imported; try again")
            with self.transaction() as conn:
                record(conn, rel)
        except BaseException:
            self._clean_partial_files()
            raise
        return rel

    def _copy_in(self, src: Path, sub: str = SCANS_DIR) -> tuple[str, str, int]:
        """Copy a file into scans/ (or ``sub``): temporary name, fsync, rename, read-only; returns (sha, rel path, size)."""
        scans = self.folder / sub
        scans.mkdir(exist_ok=True)
        tmp = scans / f".import-{uuid.uuid4().hex}"
        h = hashlib.sha256()
        with open(src, "rb") as fin, open(tmp, "wb") as fout:
            while block := fin.read(8 << 20):
                h.update(block)
                fout.write(block)
            fout.flush()
            os.fsync(fout.fileno())
        sha = h.hexdigest()
        safe = "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in src.name)
        rel = f"{sub}/{sha[:16]}_{safe}"
        final = self.folder / rel
        if final.exists():
            tmp.unlink()
        else:
            os.replace(tmp, final)
            final.chmod(0o444)
        return sha, rel, src.stat().st_size

    def import_files(self, epoch: str, paths: Iterable[str | os.PathLike], role: str, *,
                     validate=None, create_epoch: Optional[dict] = None) -> list[str]:
        """Validate, copy in and register scan files of an epoch, all or nothing.

        ``validate(path)`` must raise on an unreadable file (before anything is changed).
        ``create_epoch`` (label, datetime, notes) creates the epoch in the same transaction.
        """
        files = [Path(p) for p in paths]
        for p in files:
            if not p.is_file():
                raise InputError(f"{p}: no such file; check the path")
        shas = [sha256_of(p) for p in files]
        if len(set(shas)) != len(shas):
            raise DuplicateImportError("the same file is given twice")
        for p, sha in zip(files, shas):
            row = self.conn.execute("SELECT epoch, original_path FROM files WHERE sha256 = ?", (sha,)).fetchone()
            if row is not None:
                raise DuplicateImportError(f"{p}: this file is already in the campaign (epoch {row['epoch']}, "
                                           f"imported from {row['original_path']}); nothing was changed")
        if validate is not None:
            for p in files:
                validate(p)
        copied = []
        try:
            for p in files:
                copied.append(self._copy_in(p))
            with self.transaction() as c:
                if create_epoch is not None:
                    c.execute("INSERT INTO epochs(label, datetime, notes, created) VALUES (?, ?, ?, ?)",
                              (create_epoch["label"], create_epoch["datetime"], create_epoch.get("notes", ""),
                               now_iso()))
                for p, (sha, rel, size) in zip(files, copied):
                    c.execute("INSERT INTO files(sha256, epoch, role, stored_path, original_path, size, imported) "
                              "VALUES (?, ?, ?, ?, ?, ?, ?)", (sha, epoch, role, rel, str(p.resolve()), size, now_iso()))
                self._log(c, "import", epoch, {"role": role, "files": [str(p) for p in files], "sha256": shas})
        except BaseException:
            self._clean_partial_files()
            raise
        return shas

    def add_epoch(self, label: str, when: str, coarse: str | os.PathLike, fines: Sequence = (), *, notes: str = "",
                  validate=None) -> str:
        if not label or not label.strip() or any(ch in label for ch in "/\\\n"):
            raise InputError(f"epoch label {label!r} is not usable (no slashes or line breaks)")
        when = parse_datetime(when)
        if self.conn.execute("SELECT 1 FROM epochs WHERE label = ?", (label,)).fetchone():
            raise InputError(f"epoch {label!r} already exists; use another --label or add-fine to add files to it")
        self.import_files(label, [coarse], "coarse", validate=validate,
                          create_epoch={"label": label, "datetime": when, "notes": notes})
        if fines:
            self.import_files(label, fines, "fine", validate=validate)
        return label

    # ------------------------------------------------------------------ results
    def save_plan(self, epoch: str, plan_json: dict, inputs_hash: str, preview: Optional[tuple[bytes, str]] = None
                  ) -> None:
        """Store an epoch's plan (and the encoded map preview it came from), dropping its old centroids."""
        with self.transaction() as c:
            c.execute("INSERT OR REPLACE INTO plans(epoch, json, inputs_hash, created) VALUES (?, ?, ?, ?)",
                      (epoch, json.dumps(plan_json), inputs_hash, now_iso()))
            if preview is not None:
                c.execute("INSERT OR REPLACE INTO map_previews(epoch, inputs_hash, arrays, annotations) "
                          "VALUES (?, ?, ?, ?)", (epoch, inputs_hash, preview[0], preview[1]))
            c.execute("INSERT OR REPLACE INTO epoch_results(epoch, stage, inputs_hash, processed) VALUES (?, ?, ?, ?)",
                      (epoch, "planned", inputs_hash, now_iso()))
            c.execute("DELETE FROM centroids WHERE epoch = ?", (epoch,))
            self._log(c, "plan", epoch, {"inputs_hash": inputs_hash})

    def stored_plan(self, epoch: str) -> Optional[StoredPlan]:
        """An epoch's plan with the inputs hash it was made from, or None when it has none."""
        from lidar.plan import ScanPlan

        row = self.conn.execute("SELECT * FROM plans WHERE epoch = ?", (epoch,)).fetchone()
        if row is None:
            return None
        doc = json.loads(row["json"])
        return StoredPlan(epoch, ScanPlan.from_json(doc), doc, row["inputs_hash"], row["created"])

    def plan(self, epoch: str):
        """An epoch's :class:`lidar.plan.ScanPlan`, or None when it has none."""
        stored = self.stored_plan(epoch)
        return None if stored is None else stored.plan

    def map_preview(self, epoch: str):
        """The stored :class:`projects.map_previews.MapPreview` of an epoch, or None."""
        from projects.store.previews import decode_preview

        row = self.conn.execute("SELECT arrays, annotations FROM map_previews WHERE epoch = ?", (epoch,)).fetchone()
        return None if row is None else decode_preview(row[0], row[1])

    def result(self, epoch: str) -> Optional[EpochResult]:
        """How far processing has taken an epoch, or None when it has not started."""
        row = self.conn.execute("SELECT * FROM epoch_results WHERE epoch = ?", (epoch,)).fetchone()
        return None if row is None else EpochResult(**dict(row))

    def save_centroids(self, epoch: str, cents: dict, inputs_hash: str, params: dict) -> None:
        with self.transaction() as c:
            c.execute("DELETE FROM centroids WHERE epoch = ?", (epoch,))
            for rid, tc in cents.items():
                xyz = [float(v) if np.isfinite(v) else None for v in tc.xyz_socs]
                c.execute("INSERT INTO centroids(epoch, reflector, found, x, y, z, cov, n, threshold, separability, "
                          "sigma_range_m, flags, n_window) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                          (epoch, rid, int(tc.found), *xyz, json.dumps(np.nan_to_num(tc.cov, nan=0.0).tolist()),
                           int(tc.n_points), _f(tc.threshold), _f(tc.separability), _f(tc.sigma_range_m),
                           json.dumps(list(tc.flags)), int(tc.n_window)))
            c.execute("INSERT OR REPLACE INTO epoch_results(epoch, stage, inputs_hash, processed) VALUES (?, ?, ?, ?)",
                      (epoch, "measured", inputs_hash, now_iso()))
            self._log(c, "measure", epoch, {"inputs_hash": inputs_hash, "params": params,
                                             "found": sum(int(t.found) for t in cents.values())})

    def centroids(self, epoch: str) -> dict[str, TargetCentroid]:
        out = {}
        for r in self.conn.execute("SELECT * FROM centroids WHERE epoch = ? ORDER BY reflector", (epoch,)):
            xyz = np.array([np.nan if r[k] is None else r[k] for k in ("x", "y", "z")], dtype=float)
            out[r["reflector"]] = TargetCentroid(
                r["reflector"], xyz, np.array(json.loads(r["cov"]), dtype=float), int(r["n"]),
                _nan(r["threshold"]), _nan(r["separability"]), tuple(json.loads(r["flags"])),
                -1 if r["n_window"] is None else int(r["n_window"]),  # -1: not recorded (schema 1)
                sigma_range_m=_nan(r["sigma_range_m"]))
        return out

    def save_displacements(self, epoch: str, baseline: str, res, inputs_hash: str) -> None:
        with self.transaction() as c:
            c.execute("DELETE FROM displacement_sets WHERE epoch = ?", (epoch,))
            c.execute("INSERT INTO displacement_sets VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                      (epoch, baseline, inputs_hash, json.dumps(np.asarray(res.normal_socs).tolist()),
                       json.dumps(np.asarray(res.reference_point_socs).tolist()), json.dumps(list(res.reference_ids)),
                       res.normal_mode, json.dumps(list(res.flags)), now_iso()))
            for d in res.displacements:
                c.execute("INSERT INTO displacements VALUES (?, ?, ?, ?, ?, ?, ?)",
                          (epoch, d.reflector, _f(d.displacement_m), _f(d.sigma_m), _f(d.vertical_m),
                           _f(d.baseline_vertical_m), json.dumps(list(d.flags))))
            for rc in res.reference_checks:
                c.execute("INSERT INTO reference_checks VALUES (?, ?, ?, ?, ?, ?, ?)",
                          (epoch, rc.reflector, _f(rc.median_change_m), _f(rc.max_change_m), int(rc.moved),
                           int(rc.missing), int(rc.suspect)))
            self._log(c, "displacements", epoch, {"baseline": baseline, "inputs_hash": inputs_hash})

    def displacement_set(self, epoch: str) -> Optional[DisplacementSet]:
        """What an epoch's displacements were computed with, or None before they are."""
        r = self.conn.execute("SELECT * FROM displacement_sets WHERE epoch = ?", (epoch,)).fetchone()
        if r is None:
            return None
        return DisplacementSet(r["epoch"], r["baseline"], r["inputs_hash"], np.array(json.loads(r["normal"]), float),
                               np.array(json.loads(r["reference_point"]), float), tuple(json.loads(r["reference_ids"])),
                               r["normal_mode"], tuple(json.loads(r["flags"])), r["processed"])

    def displacements(self) -> list[DisplacementRecord]:
        """Every stored displacement, by epoch date then target (see :func:`projects.history.histories`)."""
        return self._displacement_records()

    def _displacement_records(self, where: str = "", args: tuple = (), *, newest_first: bool = False,
                              limit: Optional[int] = None) -> list[DisplacementRecord]:
        """Displacement records, optionally narrowed by ``where``.

        ``where`` is SQL over ``d`` displacements and ``e`` epochs, with ``args``: the store's own
        queries only, never a caller's text.
        """
        order = "DESC" if newest_first else "ASC"
        q = f"""SELECT e.label AS epoch, e.datetime AS datetime, d.reflector, d.displacement_m, d.sigma_m,
                      d.flags AS flags, s.flags AS epoch_flags, s.baseline
               FROM displacements d JOIN displacement_sets s ON s.epoch = d.epoch
               JOIN epochs e ON e.label = d.epoch {'WHERE ' + where if where else ''}
               ORDER BY e.datetime {order}, e.label {order}, d.reflector""" + (f" LIMIT {int(limit)}" if limit else "")
        return [DisplacementRecord(r["epoch"], r["datetime"], r["reflector"], r["displacement_m"], r["sigma_m"],
                                   tuple(json.loads(r["flags"])), tuple(json.loads(r["epoch_flags"])), r["baseline"])
                for r in self.conn.execute(q, args)]

    def last_displacement(self, reflector: str, *, at_or_before: str) -> Optional[DisplacementRecord]:
        """A target's latest displacement with a value, in an epoch dated no later than epoch ``at_or_before``."""
        rows = self._displacement_records("d.reflector = ? AND d.displacement_m IS NOT NULL AND e.datetime <= "
                                          "(SELECT datetime FROM epochs WHERE label = ?)", (reflector, at_or_before),
                                          newest_first=True, limit=1)
        return rows[0] if rows else None

    def displacement_flags(self, epoch: str) -> list[str]:
        """Every per-target displacement flag of an epoch (one entry per target and flag)."""
        rows = self.conn.execute("SELECT flags FROM displacements WHERE epoch = ?", (epoch,)).fetchall()
        return [f for r in rows for f in json.loads(r[0])]

    def reference_checks(self, epoch: str) -> list[ReferenceCheck]:
        """How each pier target moved in an epoch."""
        return [ReferenceCheck(r["epoch"], r["reflector"], r["median_change_m"], r["max_change_m"], bool(r["moved"]),
                               bool(r["missing"]), bool(r["suspect"]))
                for r in self.conn.execute("SELECT * FROM reference_checks WHERE epoch = ?", (epoch,))]

    # ------------------------------------------------------------------ limits
    def set_limit(self, reflector: str, rule: str) -> None:
        from projects.store.limits import parse_rule

        lim = parse_rule(rule, self.span_m)
        if reflector != "*":
            self.reflector(reflector)
        with self.transaction() as c:
            c.execute("INSERT OR REPLACE INTO limits VALUES (?, ?, ?, ?)",
                      (reflector, lim.warning_mm, lim.alarm_mm, rule))
            self._log(c, "limit", None, {"reflector": reflector, "rule": rule})

    def limit_for(self, reflector: str):
        from projects.store.limits import Limit

        row = self.conn.execute("SELECT * FROM limits WHERE reflector = ?", (reflector,)).fetchone() or \
            self.conn.execute("SELECT * FROM limits WHERE reflector = '*'").fetchone()
        return None if row is None else Limit(row["warning_mm"], row["alarm_mm"], row["rule"])

    def limits(self) -> list[LimitRecord]:
        """Every limit set, by target ("*" is the default for all measurement targets)."""
        from projects.store.limits import Limit

        return [LimitRecord(r["reflector"], Limit(r["warning_mm"], r["alarm_mm"], r["rule"]))
                for r in self.conn.execute("SELECT * FROM limits ORDER BY reflector")]

    def integrity_check(self) -> str:
        res = self.conn.execute("PRAGMA integrity_check").fetchone()[0]
        fk = self.conn.execute("PRAGMA foreign_key_check").fetchall()
        return res if not fk else f"foreign key violations: {len(fk)}"


def _reflector(r: sqlite3.Row) -> Reflector:
    return Reflector(r["id"], r["grp"], (r["x"], r["y"], r["z"]), r["diameter_m"],
                     (_nan(r["nx"]), _nan(r["ny"]), _nan(r["nz"])), r["installed"], r["retired"], r["replaces"],
                     r["note"])


def _f(v) -> Optional[float]:
    return float(v) if v is not None and np.isfinite(v) else None


"""The campaign's SQLite connection: database failures become one clear line, never a traceback.

SQLite reports a full disk (``database or disk is full``, or a ``disk I/O error`` when it cannot
even grow its shared-memory file), a damaged file (``database disk image is malformed``, ``file is
not a database``) and failing hardware (``disk I/O error``) as exceptions from any statement or any
row fetched. :class:`StoreConnection` and its cursors turn exactly those into
:class:`~common.files.DiskFullError` or :class:`~projects.store.errors.CampaignError` naming the
database file and what to do; every other error (a constraint, a programming mistake) passes
unchanged. A transaction that fails this way is rolled back by SQLite: the campaign is unchanged.
"""
from __future__ import annotations

import sqlite3
import urllib.parse
from pathlib import Path

from common.errors import SurveyError
from common.files import MB, disk_full_error, free_bytes
from projects.store.errors import CampaignError


def store_error(exc: sqlite3.Error, db: Path) -> SurveyError | None:
    """The one-line error for a database failure of ``db``, or None for an error that is not one."""
    name = getattr(exc, "sqlite_errorname", "") or ""
    text = str(exc)
    if name == "SQLITE_FULL" or "database or disk is full" in text:
        size = db.stat().st_size if db.exists() else 0
        return disk_full_error(db, max(32 * MB, size // 10))
    if name.startswith("SQLITE_IOERR") or "disk I/O error" in text:
        free = free_bytes(db)
        if free is not None and free < MB:
            return disk_full_error(db)
        return CampaignError(f"{db}: reading or writing the database failed (disk I/O error); check the device, "
                             f"then run 'bridgesurvey verify {db.parent}'")
    if name.startswith("SQLITE_READONLY") or "readonly database" in text:
        return CampaignError(f"{db}: the database cannot be written (read-only file, folder or medium); nothing was "
                             f"changed: make {db.name}, its -wal and -shm files and its folder writable (e.g. chmod "
                             "u+w) and run the command again")
    if name.startswith("SQLITE_CANTOPEN") or "unable to open database" in text:
        return CampaignError(f"{db}: the database cannot be opened any more ({text}): was the campaign folder moved, "
                             "renamed or made read-only while the command ran? Run the command again where it is now")
    if name == "SQLITE_NOTADB" or "not a database" in text:
        return CampaignError(f"{db}: not a readable campaign database ({text}); restore campaign.sqlite from a "
                             "backup")
    if name.startswith("SQLITE_CORRUPT") or "malformed" in text:
        return CampaignError(f"{db}: the database is damaged ({text}); run 'bridgesurvey verify {db.parent}', "
                             "and restore campaign.sqlite from a backup if it says so")
    return None


def _raise(exc: sqlite3.Error, conn: sqlite3.Connection) -> None:
    err = store_error(exc, getattr(conn, "db_path", Path("campaign.sqlite")))
    if err is not None:
        raise err from None


class StoreCursor(sqlite3.Cursor):
    """A cursor whose failures are translated by :func:`store_error`."""

    def execute(self, sql, parameters=(), /):
        try:
            return super().execute(sql, parameters)
        except sqlite3.Error as exc:
            _raise(exc, self.connection)
            raise

    def executemany(self, sql, seq_of_parameters, /):
        try:
            return super().executemany(sql, seq_of_parameters)
        except sqlite3.Error as exc:
            _raise(exc, self.connection)
            raise

    def fetchone(self):
        try:
            return super().fetchone()
        except sqlite3.Error as exc:
            _raise(exc, self.connection)
            raise

    def fetchall(self):
        try:
            return super().fetchall()
        except sqlite3.Error as exc:
            _raise(exc, self.connection)
            raise

    def fetchmany(self, size: int | None = 1):
        try:
            return super().fetchmany(size)
        except sqlite3.Error as exc:
            _raise(exc, self.connection)
            raise

    def __next__(self):
        try:
            return super().__next__()
        except sqlite3.Error as exc:
            _raise(exc, self.connection)
            raise


class StoreConnection(sqlite3.Connection):
    """A connection whose statements, fetches and commits are translated by :func:`store_error`."""

    db_path: Path = Path("campaign.sqlite")

    def cursor(self, factory=None):
        return super().cursor(factory or StoreCursor)

    def execute(self, sql, parameters=(), /):
        cur = self.cursor()
        cur.execute(sql, parameters)
        return cur

    def executemany(self, sql, parameters, /):
        cur = self.cursor()
        cur.executemany(sql, parameters)
        return cur

    def commit(self) -> None:
        try:
            super().commit()
        except sqlite3.Error as exc:
            _raise(exc, self)
            raise

    def __exit__(self, *exc_info):
        try:
            return super().__exit__(*exc_info)
        except sqlite3.Error as exc:
            _raise(exc, self)
            raise


def connect(db: Path, *, uri: str | None = None, timeout: float = 30.0) -> StoreConnection:
    """A :class:`StoreConnection` to ``db`` (or to the SQLite ``uri`` naming it), rows as ``sqlite3.Row``."""
    try:
        conn = sqlite3.connect(uri or db, timeout=timeout, factory=StoreConnection, uri=uri is not None)
    except sqlite3.Error as exc:
        err = store_error(exc, db)
        if err is not None:
            raise err from None
        raise CampaignError(f"{db}: cannot be opened ({exc})") from None
    assert isinstance(conn, StoreConnection)
    conn.db_path = Path(db)
    conn.row_factory = sqlite3.Row
    return conn


def open_database(db: Path, *, writable: bool) -> StoreConnection:
    """The campaign database opened for work: foreign keys on, WAL journal, full sync.

    A reader on a full disk or a read-only medium, where SQLite cannot create its shared-memory
    file, reads anyway: the file opened immutable when no write-ahead log holds data, else with an
    exclusive SQLite lock (which needs no shared memory). A writer gets the one-line error.
    """
    conn = connect(db)
    try:
        conn.execute("PRAGMA foreign_keys = ON")
        conn.execute("PRAGMA journal_mode = WAL")
        conn.execute("PRAGMA synchronous = FULL")
        conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except (SurveyError, sqlite3.OperationalError) as exc:
        conn.close()
        if writable:
            raise
        try:  # a reader on a full disk or a read-only medium reads without the shared-memory file
            return _open_without_shm(db)
        except Exception:
            raise exc from None
    except BaseException:
        conn.close()
        raise
    return conn


def _open_without_shm(db: Path) -> StoreConnection:
    wal = db.with_name(db.name + "-wal")
    if wal.exists() and wal.stat().st_size > 0:  # committed changes still in the log: read it, exclusively
        conn = connect(db)
        try:
            conn.execute("PRAGMA locking_mode = EXCLUSIVE")
            conn.execute("PRAGMA foreign_keys = ON")
            conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
        except BaseException:
            conn.close()
            raise
        return conn
    uri = "file:" + urllib.parse.quote(str(db.absolute())) + "?mode=ro&immutable=1"
    conn = connect(db, uri=uri)
    try:
        conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except BaseException:
        conn.close()
        raise
    return conn

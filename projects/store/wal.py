"""Which database a write-ahead log belongs to: a restored campaign.sqlite never reads another one's log.

SQLite keeps a campaign's latest transactions in ``campaign.sqlite-wal`` until a checkpoint copies them
into the database file. A process killed before that leaves the log beside the database; the next
open reads it, as it should. But a log is only pages: an *older* ``campaign.sqlite`` restored from a
backup beside the log of a later run would be read through that log, the old file's pages mixed with
the new run's, served without a word.

The log's header carries its own salts (new each time the log starts again) and SQLite writes the
database file only when it checkpoints. So the store checkpoints itself (automatic checkpoints off:
:func:`no_automatic_checkpoints`), and around each checkpoint records in ``campaign.sqlite-wal.owner``
the database file the log is written against (its size and modification time) and the log's salts:

* before: ``{"state": "checkpointing", "wal": salts, "db": the file before}``;
* after: ``{"state": "ok", "db": the file after}``.

A log with frames is then read only beside the file it was written against (or in the middle of a
checkpoint of that same log, which SQLite completes); any other is refused in one line naming what to
remove (:func:`check`). A campaign without the record (older BridgeSurvey) is read as before. Writers
and readers exclude each other (:mod:`projects.store.lock`), so the record and the files are seen at
one moment.
"""
from __future__ import annotations

import contextlib
import json
import os
import sqlite3
import struct
from pathlib import Path

from projects.store.errors import CampaignError

#: The record of the database file the write-ahead log belongs to, beside ``campaign.sqlite``.
OWNER_SUFFIX = "-wal.owner"
_MAGIC = (0x377F0682, 0x377F0683)
_HEADER = 32
_FRAME_HEADER = 24


def wal_path(db: Path) -> Path:
    """The write-ahead log of database ``db``."""
    return db.with_name(db.name + "-wal")


def owner_path(db: Path) -> Path:
    """The record of which database file the log of ``db`` belongs to."""
    return db.with_name(db.name + OWNER_SUFFIX)


def wal_salts(db: Path) -> list[int] | None:
    """(checkpoint sequence, salt-1, salt-2) of the log beside ``db`` when it holds frames, else None.

    A log holds frames when its first frame carries the header's salts (a log that was reset, or
    truncated, or is shorter than one frame, holds none that SQLite would read).
    """
    try:
        with open(wal_path(db), "rb") as fh:
            head = fh.read(_HEADER + _FRAME_HEADER)
    except FileNotFoundError:
        return None
    except OSError:
        return None
    if len(head) < _HEADER + _FRAME_HEADER:
        return None
    magic, _version, _page, seq, salt1, salt2 = struct.unpack(">6I", head[:24])
    if magic not in _MAGIC:
        return None
    f_salt1, f_salt2 = struct.unpack(">2I", head[_HEADER + 8:_HEADER + 16])
    if (f_salt1, f_salt2) != (salt1, salt2):
        return None
    return [seq, salt1, salt2]


def _print(db: Path) -> list[int] | None:
    try:
        st = db.stat()
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def _read_owner(db: Path) -> dict | None:
    try:
        doc = json.loads(owner_path(db).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def _write_owner(db: Path, doc: dict) -> None:
    """Write the record through a temporary file and a rename (a kill leaves the old one or the new one)."""
    path = owner_path(db)
    tmp = path.with_name(f".{path.name}.part")
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(doc, fh)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def check(db: Path) -> None:
    """Refuse (one line) a write-ahead log with frames that does not belong to the database file beside it."""
    salts = wal_salts(db)
    if salts is None:
        return
    owner = _read_owner(db)
    if owner is None:
        return  # no record (a campaign of an older BridgeSurvey, or a medium it could not be written to)
    if owner.get("db") == _print(db):
        return
    if owner.get("state") == "checkpointing" and owner.get("wal") == salts:
        return  # killed while copying this very log into this file: SQLite completes it
    wal = wal_path(db)
    raise CampaignError(f"{db}: the write-ahead log {wal.name} beside it belongs to another version of the database "
                        f"(campaign.sqlite restored from a backup while the log of a later run was left?); nothing "
                        f"was read or changed: move {wal.name} and {db.name}-shm out of {db.parent} (keep them until "
                        "the campaign reads well), then run the command again")


def no_automatic_checkpoints(conn: sqlite3.Connection) -> None:
    """Leave checkpoints to :func:`checkpoint` (SQLite's own would write the database file unrecorded)."""
    conn.execute("PRAGMA wal_autocheckpoint = 0")


def checkpoint(conn: sqlite3.Connection, db: Path) -> None:
    """Copy the log into the database file and empty it, recording which file the log belongs to before and after.

    A writer calls it when it opens and before it closes; a medium where the record cannot be written
    (read-only, full) leaves the checkpoint to SQLite as before.
    """
    try:
        _write_owner(db, {"state": "checkpointing", "wal": wal_salts(db), "db": _print(db)})
    except OSError:
        return
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
    with contextlib.suppress(OSError):
        _write_owner(db, {"state": "ok", "db": _print(db)})

"""The campaign's tables beside the core ones, each behind a small repository object.

A :class:`projects.store.campaign.Campaign` owns the connection, the lock and the transactions; it
hangs one repository per concern off itself (``campaign.series``, ``campaign.events``,
``campaign.predictions``, ``campaign.crossvals``, ``campaign.comparisons``). A repository holds a
back-reference to that core and nothing else: the SQL of its tables lives here, and callers get the
typed records of :mod:`projects.store.records`, never rows. What they store carries a digest
(:mod:`projects.store.digests`); a stored document that no longer matches it is never handed out.
"""
from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Sequence
from contextlib import AbstractContextManager as ContextManager
from pathlib import Path
from typing import Protocol

from common.files import sha256_of
from projects.store import digests
from projects.store.errors import CampaignError, DuplicateImportError, InputError
from projects.store.records import (
    ComparisonRecord,
    CrossvalRecord,
    EventRecord,
    PredictionRecord,
    SeriesRecord,
    now_iso,
)

SERIES_TABLES = {"camera_series": "camera", "env_series": "environment"}


class StoreCore(Protocol):
    """What a repository needs from the campaign that owns it."""

    conn: sqlite3.Connection

    def transaction(self) -> ContextManager[sqlite3.Connection]:
        """One atomic change (see :meth:`projects.store.campaign.Campaign.transaction`)."""
        ...

    def log_action(self, conn: sqlite3.Connection, action: str, epoch: str | None, details: dict) -> None:
        """Add a line to the campaign's log inside the transaction ``conn``."""
        ...

    def is_sound(self, table: str, key: Sequence) -> bool:
        """Whether a stored group still matches its digest."""
        ...


def _series_table(table: str) -> str:
    if table not in SERIES_TABLES:
        raise ValueError(f"not a series table: {table!r}")
    return table


class _Repository:
    """A repository: a back-reference to the campaign core that owns the connection."""

    def __init__(self, core: StoreCore):
        self._core = core

    @property
    def _conn(self) -> sqlite3.Connection:
        return self._core.conn


class SeriesRepository(_Repository):
    """Imported camera and environment series (tables ``camera_series`` and ``env_series``)."""

    def check_new(self, table: str, path: str | os.PathLike, name: str | None, what: str) -> tuple[Path, str]:
        """The file and the name of a series about to be imported into ``table``.

        The file exists and the name (default: the file's stem) is usable and free; ``what`` names
        the kind of series in the messages ("a camera series").
        """
        table = _series_table(table)
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: no such file; check the path")
        name = (name or path.stem).strip()
        if not name or any(ch in name for ch in "/\\\n"):
            raise InputError(f"series name {name!r} is not usable")
        if self._conn.execute(f"SELECT 1 FROM {table} WHERE name = ?", (name,)).fetchone():
            raise InputError(f"{what} named {name!r} is already in the campaign; give another --name")
        return path, name

    def checksum_if_new(self, table: str, path: Path) -> str:
        """The file's sha256, refusing a file already imported into ``table`` under some series name."""
        table = _series_table(table)
        sha = sha256_of(path)
        row = self._conn.execute(f"SELECT name, original_path FROM {table} WHERE sha256 = ?", (sha,)).fetchone()
        if row is not None:
            raise DuplicateImportError(f"{path}: this file is already in the campaign as series {row['name']!r} "
                                       f"(from {row['original_path']}); nothing was changed")
        return sha

    def insert(self, conn: sqlite3.Connection, table: str, *, name: str, sha256: str, stored_path: str,
               original_path: str, options: dict, summary: dict, arrays: bytes,
               reflector: str | None = None, kind: str | None = None) -> None:
        """Record an imported series inside the import's transaction (see ``Campaign.import_file``)."""
        table = _series_table(table)
        # the one column the two tables do not share: the watched target, or the environment quantity
        col, value = ("reflector", reflector) if table == "camera_series" else ("kind", kind)
        conn.execute(f"INSERT INTO {table}(name, {col}, sha256, stored_path, original_path, imported, options, "
                     "summary, arrays) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                     (name, value, sha256, stored_path, original_path, now_iso(), json.dumps(options),
                      json.dumps(summary), arrays))
        digests.seal(conn, table, (name,))

    def records(self, table: str, *, kind: str | None = None, name: str | None = None) -> list[SeriesRecord]:
        """The imported series of ``table`` (``camera_series`` or ``env_series``), oldest import first.

        Optionally of one environment ``kind`` or one ``name``.
        """
        table = _series_table(table)
        what = "reflector, NULL AS kind" if table == "camera_series" else "NULL AS reflector, kind"
        q = f"SELECT name, {what}, sha256, stored_path, original_path, imported, options, summary FROM {table}"
        args: tuple = ()
        if name is not None:
            q, args = q + " WHERE name = ?", (name,)
        elif kind is not None and table == "env_series":
            q, args = q + " WHERE kind = ?", (kind,)
        return [SeriesRecord(r["name"], r["kind"] or SERIES_TABLES[table], r["reflector"], r["sha256"],
                             r["stored_path"], r["original_path"], r["imported"], json.loads(r["options"]),
                             json.loads(r["summary"]))
                for r in self._conn.execute(q + " ORDER BY imported, name", args)]

    def arrays(self, table: str, name: str) -> bytes:
        """The stored arrays (npz bytes: time_ns and values) of one series."""
        table = _series_table(table)
        row = self._conn.execute(f"SELECT arrays FROM {table} WHERE name = ?", (name,)).fetchone()
        if row is None:
            raise KeyError(name)
        if not self._core.is_sound(table, (name,)):
            raise CampaignError(f"the stored {digests.GROUPS[table].name} {name!r} is damaged (it no longer matches "
                                "its checksum); run 'bridgesurvey repair' on the campaign to read it again from its file")
        return row[0]


class EventRepository(_Repository):
    """Construction steps, loads and repairs that explain the displacements (table ``events``)."""

    def add(self, date: str, kind: str, label: str, load_kn_m: float | None) -> int:
        """Record an event (already checked) and log it; returns its id."""
        with self._core.transaction() as conn:
            cur = conn.execute("INSERT INTO events(date, kind, label, load_kn_m, created) VALUES (?, ?, ?, ?, ?)",
                               (date, kind, label, load_kn_m, now_iso()))
            self._core.log_action(conn, "event-add", None, {"id": cur.lastrowid, "date": date, "kind": kind,
                                                            "label": label})
        return int(cur.lastrowid or 0)

    def all(self) -> list[EventRecord]:
        """The campaign's events, by date."""
        return [EventRecord(r["id"], r["date"], r["kind"], r["label"], r["load_kn_m"])
                for r in self._conn.execute("SELECT id, date, kind, label, load_kn_m FROM events ORDER BY date, id")]


class PredictionRepository(_Repository):
    """The design prediction of each target (table ``predictions``)."""

    def put(self, conn: sqlite3.Connection, reflector: str, *, sha256: str, stored_path: str, original_path: str,
            options: dict, arrays: bytes) -> None:
        """Record (or replace) a target's prediction inside the import's transaction."""
        conn.execute("INSERT OR REPLACE INTO predictions(reflector, sha256, stored_path, original_path, imported, "
                     "options, arrays) VALUES (?, ?, ?, ?, ?, ?, ?)",
                     (reflector, sha256, stored_path, original_path, now_iso(), json.dumps(options), arrays))
        digests.seal(conn, "predictions", (reflector,))

    def all(self) -> list[PredictionRecord]:
        """Every target's stored prediction, by target (one that fails its digest is left out)."""
        return [PredictionRecord(r["reflector"], json.loads(r["options"]), r["arrays"], r["sha256"],
                                 r["stored_path"], r["original_path"])
                for r in self._conn.execute("SELECT reflector, options, arrays, sha256, stored_path, original_path "
                                            "FROM predictions ORDER BY reflector").fetchall()
                if self._core.is_sound("predictions", (r["reflector"],))]


class CrossvalRepository(_Repository):
    """Cross-validations of the camera series with the LiDAR epochs (table ``crossvals``)."""

    def save(self, series: str, summary: dict, details: dict) -> None:
        """Keep a camera series' cross-validation summary (JSON-safe document) and log ``details``."""
        with self._core.transaction() as conn:
            conn.execute("INSERT OR REPLACE INTO crossvals(series, summary, created) VALUES (?, ?, ?)",
                         (series, json.dumps(summary), now_iso()))
            digests.seal(conn, "crossvals", (series,))
            self._core.log_action(conn, "crossval", None, details)

    def all(self) -> list[CrossvalRecord]:
        """Every stored cross-validation, by series name (one that fails its digest is stale: left out)."""
        return [CrossvalRecord(r["series"], json.loads(r["summary"]), r["created"])
                for r in self._conn.execute("SELECT series, summary, created FROM crossvals ORDER BY series").fetchall()
                if self._core.is_sound("crossvals", (r["series"],))]


class ComparisonRepository(_Repository):
    """Whole-scan comparisons of two epochs (table ``comparisons``)."""

    def save(self, summary: dict) -> None:
        """Keep a comparison's JSON summary (``from``, ``to``, ``method`` ...) and log it."""
        with self._core.transaction() as conn:
            conn.execute("INSERT OR REPLACE INTO comparisons(from_epoch, to_epoch, method, summary, created) "
                         "VALUES (?, ?, ?, ?, ?)", (summary["from"], summary["to"], summary["method"],
                                                    json.dumps(summary, default=float), now_iso()))
            digests.seal(conn, "comparisons", (summary["from"], summary["to"], summary["method"]))
            self._core.log_action(conn, "compare", summary["to"], {"from": summary["from"],
                                                                   "method": summary["method"]})

    def all(self) -> list[ComparisonRecord]:
        """Stored comparisons, oldest first (one that fails its digest is stale: left out)."""
        return [ComparisonRecord(r["from_epoch"], r["to_epoch"], r["method"], json.loads(r["summary"]), r["created"])
                for r in self._conn.execute("SELECT from_epoch, to_epoch, method, summary, created FROM comparisons "
                                            "ORDER BY created").fetchall()
                if self._core.is_sound("comparisons", (r["from_epoch"], r["to_epoch"], r["method"]))]

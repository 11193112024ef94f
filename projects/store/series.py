"""The campaign store's tables of imported series, events, predictions, cross-validations and comparisons.

Part of :class:`projects.store.Campaign` (a base class of it): the SQL of these tables lives here,
and callers get records (:mod:`projects.store.records`) or decoded JSON documents, never rows.
"""
from __future__ import annotations

import json
import sqlite3
from typing import ContextManager, Optional

from projects.store.records import EventRecord, PredictionRecord, SeriesRecord

SERIES_TABLES = {"camera_series": "camera", "env_series": "environment"}


def _now() -> str:
    from projects.store.campaign import now_iso

    return now_iso()


class SeriesTables:
    """Imported series and what is derived from them; mixed into :class:`projects.store.Campaign`."""

    conn: sqlite3.Connection

    # provided by Campaign
    def transaction(self) -> ContextManager[sqlite3.Connection]:
        raise NotImplementedError

    def _log(self, conn: sqlite3.Connection, action: str, epoch: Optional[str], details: dict) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ camera and environment series
    def insert_series(self, conn: sqlite3.Connection, table: str, *, name: str, sha256: str, stored_path: str,
                      original_path: str, options: dict, summary: dict, arrays: bytes,
                      reflector: Optional[str] = None, kind: Optional[str] = None) -> None:
        """Record an imported series inside the import's transaction (see ``Campaign.import_file``)."""
        if table not in SERIES_TABLES:
            raise ValueError(f"not a series table: {table!r}")
        # the one column the two tables do not share: the watched target, or the environment quantity
        col, value = ("reflector", reflector) if table == "camera_series" else ("kind", kind)
        conn.execute(f"INSERT INTO {table}(name, {col}, sha256, stored_path, original_path, imported, options, "
                     "summary, arrays) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                     (name, value, sha256, stored_path, original_path, _now(), json.dumps(options),
                      json.dumps(summary), arrays))

    def series(self, table: str, *, kind: Optional[str] = None, name: Optional[str] = None) -> list[SeriesRecord]:
        """The imported series of ``table`` (``camera_series`` or ``env_series``), oldest import first.

        Optionally of one environment ``kind`` or one ``name``.
        """
        if table not in SERIES_TABLES:
            raise ValueError(f"not a series table: {table!r}")
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
                for r in self.conn.execute(q + " ORDER BY imported, name", args)]

    def series_arrays(self, table: str, name: str) -> bytes:
        """The stored arrays (npz bytes: time_ns and values) of one series."""
        if table not in SERIES_TABLES:
            raise ValueError(f"not a series table: {table!r}")
        row = self.conn.execute(f"SELECT arrays FROM {table} WHERE name = ?", (name,)).fetchone()
        if row is None:
            raise KeyError(name)
        return row[0]

    # ------------------------------------------------------------------ cross-validations
    def save_crossval_summary(self, series: str, summary: dict, details: dict) -> None:
        """Keep a camera series' cross-validation summary (JSON-safe document) and log it."""
        with self.transaction() as conn:
            conn.execute("INSERT OR REPLACE INTO crossvals(series, summary, created) VALUES (?, ?, ?)",
                         (series, json.dumps(summary), _now()))
            self._log(conn, "crossval", None, details)

    def crossval_summaries(self) -> list[dict]:
        """Every stored cross-validation summary, by series name."""
        return [json.loads(r[0]) for r in self.conn.execute("SELECT summary FROM crossvals ORDER BY series")]

    # ------------------------------------------------------------------ events
    def insert_event(self, date: str, kind: str, label: str, load_kn_m: Optional[float]) -> int:
        """Record an event (already checked) and log it; returns its id."""
        with self.transaction() as conn:
            cur = conn.execute("INSERT INTO events(date, kind, label, load_kn_m, created) VALUES (?, ?, ?, ?, ?)",
                               (date, kind, label, load_kn_m, _now()))
            self._log(conn, "event-add", None, {"id": cur.lastrowid, "date": date, "kind": kind,
                                                "label": label})
        return int(cur.lastrowid or 0)

    def events(self) -> list[EventRecord]:
        """The campaign's events, by date."""
        return [EventRecord(r["id"], r["date"], r["kind"], r["label"], r["load_kn_m"])
                for r in self.conn.execute("SELECT id, date, kind, label, load_kn_m FROM events ORDER BY date, id")]

    # ------------------------------------------------------------------ design predictions
    def insert_prediction(self, conn: sqlite3.Connection, reflector: str, *, sha256: str, stored_path: str,
                          original_path: str, options: dict, arrays: bytes) -> None:
        """Record (or replace) a target's prediction inside the import's transaction."""
        conn.execute("INSERT OR REPLACE INTO predictions(reflector, sha256, stored_path, original_path, imported, "
                     "options, arrays) VALUES (?, ?, ?, ?, ?, ?, ?)",
                     (reflector, sha256, stored_path, original_path, _now(), json.dumps(options), arrays))

    def prediction_records(self) -> list[PredictionRecord]:
        return [PredictionRecord(r["reflector"], json.loads(r["options"]), r["arrays"])
                for r in self.conn.execute("SELECT reflector, options, arrays FROM predictions ORDER BY reflector")]

    # ------------------------------------------------------------------ whole-scan comparisons
    def save_comparison_summary(self, summary: dict) -> None:
        """Keep a comparison's JSON summary (``from``, ``to``, ``method`` ...) and log it."""
        with self.transaction() as conn:
            conn.execute("INSERT OR REPLACE INTO comparisons VALUES (?, ?, ?, ?, ?)",
                         (summary["from"], summary["to"], summary["method"], json.dumps(summary, default=float),
                          _now()))
            self._log(conn, "compare", summary["to"], {"from": summary["from"],
                                                       "method": summary["method"]})

    def comparison_summaries(self) -> list[dict]:
        """Stored comparison summaries, oldest first."""
        return [json.loads(r[0]) for r in self.conn.execute("SELECT summary FROM comparisons ORDER BY created")]

"""Putting a campaign right again after a restore or damage, without ever deleting an imported file.

* :func:`repair_schema_version`: a ``meta.schema_version`` that is missing or unreadable is set
  again from what the tables show (:func:`projects.store.schema.inferred_version`).
* :func:`repair_campaign`: every file in the import folders that the database does not list, and
  that the journal of imports (:mod:`projects.store.journal`) knows, is registered again when its
  checksum (and, for a scan, its header) still matches its import: a scan into its epoch (the
  epoch is created again with its recorded date and notes when the database lost it too); a camera
  or environment series or a prediction is read again from its file with the options it was
  imported with, by the ``reimporters`` the caller passes (reading them is the series layer's job).
  Series whose stored arrays fail their digest are read again the same way. Damaged results are
  left to ``process``, which recomputes them.

Each step is its own transaction and is logged; what could not be done is said with the reason.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from common.errors import SurveyError
from common.files import sha256_of
from projects.store import digests, journal, schema
from projects.store.campaign import DB_NAME, Campaign
from projects.store.connection import connect
from projects.store.errors import CampaignError
from projects.store.imports import header_matches
from projects.store.lock import CampaignLock

#: ``reimporter(campaign, stored_file, journal_entry) -> what it did`` for a kind of series file.
Reimporter = Callable[[Campaign, Path, dict], str]


@dataclass
class RepairReport:
    """What a repair did, and what it could not do (each a line, with the reason)."""

    done: list[str] = field(default_factory=list)
    left: list[str] = field(default_factory=list)


def repair_schema_version(folder: str | os.PathLike) -> str | None:
    """Set a missing or unreadable schema version from the tables; returns what it did, None when it was fine.

    Holds the writer lock while it looks; a version newer than this BridgeSurvey is left alone.
    """
    folder = Path(folder)
    db = folder / DB_NAME
    if not db.is_file():
        raise CampaignError(f"{folder}: no campaign here (no {DB_NAME})")
    lock = CampaignLock.acquire(folder, exclusive=True)
    try:
        conn = connect(db)
        try:
            try:
                schema.version_of(conn, str(folder))
                return None
            except CampaignError:
                pass
            version = schema.inferred_version(conn)
            if version < 1:
                raise CampaignError(f"{db}: its tables are not a campaign's; restore campaign.sqlite from a backup")
            before = schema.recorded_version(conn)
            with conn:
                conn.execute("INSERT OR REPLACE INTO meta(key, value) VALUES ('schema_version', ?)", (str(version),))
            return (f"schema version set to {version} from the tables (it was "
                    f"{'not recorded' if before is None else repr(before)})")
        finally:
            conn.close()
    finally:
        lock.release()


def _register_scan(c: Campaign, rel: str, e: dict) -> str:
    """Register an unlisted scan file again from its journal entry (creating its epoch when it is gone too)."""
    label = e["epoch"]
    created = False
    with c.transaction() as conn:
        if conn.execute("SELECT 1 FROM epochs WHERE label = ?", (label,)).fetchone() is None:
            conn.execute("INSERT INTO epochs(label, datetime, notes, created) VALUES (?, ?, ?, ?)",
                         (label, e["epoch_datetime"], e.get("epoch_notes", ""), e.get("imported", "")))
            created = True
        conn.execute("INSERT INTO files(sha256, epoch, role, stored_path, original_path, size, imported, setup, frame) "
                     "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)", (e["sha256"], label, e["role"], rel,
                                                            e.get("original_path", ""), int(e["size"]),
                                                            e.get("imported", ""), int(e.get("setup") or 1),
                                                            e.get("frame")))
        c.log_action(conn, "repair", label, {"registered": rel, "role": e["role"], "epoch_created": created})
    return f"{rel}: registered again as the {e['role']} scan of epoch {label}" + \
        (" (the epoch was created again with its recorded date)" if created else "")


def _check_entry(c: Campaign, rel: str, e: dict | None, sha_by_path: dict[str, str]) -> str | None:
    """Why an unlisted file cannot be registered again, or None when it can."""
    if e is None:
        return (f"{rel}: not in the journal of imports, so BridgeSurvey cannot tell what it was imported as; "
                "import it again if it belongs to the campaign (it was left as it is)")
    sha = sha256_of(c.folder / rel)
    sha_by_path[rel] = sha
    if sha != e.get("sha256") or not Path(rel).name.startswith(sha[:16]):
        return (f"{rel}: its checksum no longer matches its import (changed or damaged); left as it is: import it "
                f"again from {e.get('original_path', 'the original')}")
    if e.get("kind") == "scan":
        if not header_matches(c.folder / rel, e.get("header")):
            return f"{rel}: its header no longer reads as it did at its import; left as it is"
        row = c.conn.execute("SELECT stored_path FROM files WHERE sha256 = ?", (sha,)).fetchone()
        if row is not None:
            return f"{rel}: the same scan is already registered as {row[0]}; left as it is"
    return None


def _reimport(c: Campaign, rel: str, e: dict, reimporters: Mapping[str, Reimporter]) -> str:
    kind = e.get("kind", "")
    if kind not in reimporters:
        raise CampaignError(f"{rel}: BridgeSurvey cannot read a {kind or 'file of unknown kind'} again here")
    what = reimporters[kind](c, c.folder / rel, e)
    if e.get("original_path"):  # the series layer recorded the stored copy as the source: keep the real one
        table = {"camera": "camera_series", "environment": "env_series", "prediction": "predictions"}.get(kind)
        if table:
            with c.transaction() as conn:
                conn.execute(f"UPDATE {table} SET original_path = ? WHERE stored_path = ?", (e["original_path"], rel))
    return what


def _damaged_series(c: Campaign, entries: dict[str, dict], reimporters: Mapping[str, Reimporter],
                    out: RepairReport) -> None:
    """Read series whose stored arrays fail their digest again from their files."""
    for table in ("camera_series", "env_series", "predictions"):
        key_col = digests.GROUPS[table].key[0]
        for (key,) in digests.damaged(c.conn, table):
            row = c.conn.execute(f"SELECT stored_path FROM {table} WHERE {key_col} = ?", (key,)).fetchone()
            rel = row[0]
            e = entries.get(rel)
            if e is None or e.get("kind") not in reimporters or not (c.folder / rel).is_file() \
                    or sha256_of(c.folder / rel) != e.get("sha256"):
                out.left.append(f"{digests.GROUPS[table].name} {key}: damaged, and its file cannot be read again "
                                "here; import it again from the original")
                continue
            with c.transaction() as conn:
                conn.execute(f"DELETE FROM {table} WHERE stored_path = ?", (rel,))
                c.log_action(conn, "repair", None, {"damaged": table, "key": key, "file": rel})
            out.done.append(_reimport(c, rel, e, reimporters) + " (its stored arrays were damaged)")


def _replay_epoch_scanners(c: Campaign, labels: set[str], out: RepairReport) -> None:
    """Give epochs created again their own scanner, when the journal recorded one."""
    if not labels:
        return
    own: dict[tuple[str, int], dict] = {}
    for e in journal.entries(c.folder):
        if e.get("kind") == "epoch-scanner" and e.get("epoch") in labels:
            own[(e["epoch"], int(e.get("setup") or 1))] = e["profile"]
    if not own:
        return
    from lidar.scanner_profile import ScannerProfile

    for (label, setup), doc in sorted(own.items()):
        c.set_profile(ScannerProfile.from_dict(doc), epoch=label, setup=setup if setup != 1 else None)
        what = f"set-up {setup}'s own scanner" if setup != 1 else "its own scanner"
        out.done.append(f"epoch {label}: {what} ({doc.get('name', '?')}) set again from the journal")


def repair_campaign(c: Campaign, reimporters: Mapping[str, Reimporter] | None = None) -> RepairReport:
    """Register again what the database lost, read damaged series again (see the module notes)."""
    reimporters = reimporters or {}
    out = RepairReport()
    entries = journal.latest_by_path(c.folder)
    before = {e.label for e in c.epochs()}
    sha_by_path: dict[str, str] = {}
    for rel in c.unlisted_files():
        e = entries.get(rel)
        why = _check_entry(c, rel, e, sha_by_path)
        if why is not None:
            out.left.append(why)
            continue
        assert e is not None
        try:
            out.done.append(_register_scan(c, rel, e) if e.get("kind") == "scan" else _reimport(c, rel, e, reimporters))
        except SurveyError as exc:  # e.g. a series its reader refuses now: say so, keep going
            out.left.append(f"{rel}: not registered again ({exc})")
    _replay_epoch_scanners(c, {e.label for e in c.epochs()} - before, out)
    _damaged_series(c, entries, reimporters, out)
    return out

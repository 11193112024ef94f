"""Putting a campaign right again after a restore or damage, without ever deleting an imported file.

* :func:`repair_schema_version`: a ``meta.schema_version`` that is missing or unreadable is set
  again from what the tables show (:func:`projects.store.schema.inferred_version`), never lower than
  it was; tables the version needs and the database lost are made again when their rows are results
  (recomputed) or are held by the journal of imports, else the one line names what it cannot mend.
* :func:`repair_campaign`: every file in the import folders that the database does not list, and
  that the journal of imports (:mod:`projects.store.journal`) knows, is registered again when its
  checksum (and, for a scan, its header) still matches its import: a scan into its epoch (the
  epoch is created again with its recorded date and notes when the database lost it too); a camera
  or environment series or a prediction is read again from its file with the options it was
  imported with, by the ``reimporters`` the caller passes (reading them is the series layer's job).
  Series whose stored arrays fail their digest are read again the same way. Scans the journal has
  archived out of the folder (:mod:`projects.store.archive`) and the database does not record so are
  recorded again where the journal says (never taken for lost). Damaged results are left to ``process``,
  which recomputes them.

Each step is its own transaction and is logged; what could not be done is said with the reason.
"""
from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from common.errors import SurveyError
from common.files import sha256_of
from lidar.scanner_profile import ScannerProfile
from projects.store import digests, journal, schema, wal
from projects.store.archive import repair_archived
from projects.store.campaign import DB_NAME, Campaign, damaged_input_line, describe_input
from projects.store.connection import connect
from projects.store.errors import CampaignError
from projects.store.imports import BY_VISIT, SCANS_DIR, header_matches, link_by_visit, visit_link_name
from projects.store.limits import parse_rule
from projects.store.lock import CampaignLock

#: ``reimporter(campaign, stored_file, journal_entry) -> what it did`` for a kind of series file.
Reimporter = Callable[[Campaign, Path, dict], str]


@dataclass
class RepairReport:
    """What a repair did, and what it could not do (each a line, with the reason)."""

    done: list[str] = field(default_factory=list)
    left: list[str] = field(default_factory=list)


#: Tables whose rows are results: made again empty when lost, their rows recomputed by ``process`` (or the
#: command that made them); a row left in another table that pointed into them is removed with them.
RECOMPUTED = frozenset({
    "plans", "map_previews", "epoch_results", "centroids", "centroid_extras", "closure_centroids",
    "displacement_sets", "displacements", "reference_checks", "displacement_extras", "displacement_set_extras",
    "field_models", "setup_plans", "setup_previews", "setup_results", "comparisons", "crossvals"})
#: Tables whose rows the journal of imports holds: made again empty, then filled by :func:`repair_campaign`.
FROM_JOURNAL = frozenset({"epochs", "files", "camera_series", "env_series", "predictions", "archived_files"})
#: The campaign's log: made again empty (its history is lost, nothing computed depends on it).
LOG = frozenset({"log"})
#: Tables whose rows the campaign's log holds: made again from the last rule set for each target.
FROM_LOG = frozenset({"limits"})


def _orphans_removed(conn) -> int:
    """Remove rows of the remade tables that point to rows that are gone (repeated until none is left)."""
    removed = 0
    for _ in range(8):
        bad = [(t, rowid) for t, rowid, *_ in conn.execute("PRAGMA foreign_key_check").fetchall()
               if t in RECOMPUTED | FROM_JOURNAL and rowid is not None]
        if not bad:
            break
        for t, rowid in bad:
            conn.execute(f"DELETE FROM {t} WHERE rowid = ?", (rowid,))
        removed += len(bad)
    return removed


def _remake_tables(conn, folder: Path, missing: list[str]) -> list[str]:
    """Make lost tables of the current schema again (see :data:`RECOMPUTED`), or raise naming what cannot be."""
    tables = [m for m in missing if "." not in m]
    lost = [m for m in missing if m not in RECOMPUTED | FROM_JOURNAL | LOG | FROM_LOG]
    if "limits" in tables and "log" in tables:
        lost.append("limits (the log that held its rules is lost too)")
    if lost:
        what = ", ".join(lost)
        raise CampaignError(f"{folder}: campaign.sqlite lacks {what}, which 'repair' cannot make again (nothing else "
                            "holds "
                            + ("them" if len(lost) > 1 else "it") + "); nothing was changed: restore campaign.sqlite "
                            "from a backup")
    conn.execute("BEGIN IMMEDIATE")
    try:
        for t in tables:
            for stmt in schema.creation_sql(t):
                conn.execute(stmt)
        removed = _orphans_removed(conn)
        rules = _limits_from_log(conn) if "limits" in tables else {}
    except BaseException:
        conn.rollback()
        raise
    conn.commit()
    out = []
    for t in tables:
        if t == "limits":
            out.append("table limits made again from the campaign's log: " + (
                "; ".join(f"{'every measurement target' if r == '*' else r} {rule}" for r, rule in rules.items())
                or "no limit had been set") + " (check them with 'bridgesurvey status')")
            continue
        how = ("its rows are recomputed by 'process'" if t in RECOMPUTED else
               "the campaign's log starts again" if t in LOG else "filled again from the journal of imports")
        out.append(f"table {t} made again ({how})")
    if removed:
        out.append(f"{removed} row(s) that belonged to the lost rows removed (they are recomputed)")
    return out


def _limits_from_log(conn) -> dict[str, str]:
    """Set the limits again, each target's last rule in the campaign's log (``limit`` lines); the rules set."""
    rules: dict[str, str] = {}
    for (details,) in conn.execute("SELECT details FROM log WHERE action = 'limit' ORDER BY id"):
        d = json.loads(details)
        if d.get("reflector") and d.get("rule"):
            rules[d["reflector"]] = d["rule"]
    row = conn.execute("SELECT value FROM meta WHERE key = 'span_m'").fetchone()
    span = float(row[0]) if row is not None and row[0] else None
    for reflector, rule in rules.items():
        lim = parse_rule(rule, span)
        conn.execute("INSERT OR REPLACE INTO limits(reflector, warning_mm, alarm_mm, rule) VALUES (?, ?, ?, ?)",
                     (reflector, lim.warning_mm, lim.alarm_mm, rule))
        digests.seal_row(conn, "limits", reflector)
    return dict(sorted(rules.items()))


def repair_schema_version(folder: str | os.PathLike) -> list[str]:
    """Put the schema right: a missing or unreadable version set from the tables, lost tables made again.

    The recorded version is never lowered: tables that a version needs and the database lacks are lost
    tables, made again when what they held can be recomputed or read again from the journal of imports
    (:data:`RECOMPUTED`, :data:`FROM_JOURNAL`), else a :class:`CampaignError` naming them (nothing changed).
    Returns what was done (empty when all was fine). Holds the writer lock; a newer version is left alone.
    """
    folder = Path(folder)
    db = folder / DB_NAME
    if not db.is_file():
        raise CampaignError(f"{folder}: no campaign here (no {DB_NAME})")
    lock = CampaignLock.acquire(folder, exclusive=True)
    try:
        wal.check(db)
        conn = connect(db)
        try:
            return _repair_schema(conn, folder, db)
        finally:
            conn.close()
    finally:
        lock.release()


def _repair_schema(conn, folder: Path, db: Path) -> list[str]:
    try:
        schema.version_of(conn, str(folder))
        return []
    except CampaignError as exc:
        if "lacks table meta" in str(exc):
            raise
    text = schema.recorded_version(conn)
    try:
        recorded: int | None = int(str(text).strip())
    except ValueError:
        recorded = None
    if recorded is not None and recorded >= 1:
        if recorded == schema.SCHEMA_VERSION:
            missing = schema.missing_parts(conn)
            columns = [m for m in missing if "." in m]
            if columns:
                raise CampaignError(f"{folder}: campaign.sqlite lacks the column(s) {', '.join(columns)} of its schema "
                                    "version, which 'repair' cannot make again; nothing was changed: restore "
                                    "campaign.sqlite from a backup")
            return _remake_tables(conn, folder, missing)
        have = schema.inferred_version(conn)
        if have < recorded:
            raise CampaignError(f"{folder}: campaign.sqlite says schema version {recorded} but lacks tables of it (its "
                                f"tables are complete only up to version {have}); 'repair' never lowers the version "
                                "and cannot make tables of an older version again: restore campaign.sqlite from a "
                                "backup")
    version = schema.inferred_version(conn)
    if version < 1:
        raise CampaignError(f"{db}: its tables are not a campaign's; restore campaign.sqlite from a backup")
    with conn:
        conn.execute("INSERT OR REPLACE INTO meta(key, value) VALUES ('schema_version', ?)", (str(version),))
    return [f"schema version set to {version} from the tables (it was "
            f"{'not recorded' if text is None else repr(text)})"]


def _register_scan(c: Campaign, rel: str, e: dict) -> str:
    """Register an unlisted scan file again from its journal entry (creating its epoch when it is gone too)."""
    label = e["epoch"]
    created = False
    with c.transaction() as conn:
        if conn.execute("SELECT 1 FROM epochs WHERE label = ?", (label,)).fetchone() is None:
            conn.execute("INSERT INTO epochs(label, datetime, notes, created) VALUES (?, ?, ?, ?)",
                         (label, e["epoch_datetime"], e.get("epoch_notes", ""), e.get("imported", "")))
            digests.seal_row(conn, "epochs", label)
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

    for (label, setup), doc in sorted(own.items()):
        c.set_profile(ScannerProfile.from_dict(doc), epoch=label, setup=setup if setup != 1 else None)
        what = f"set-up {setup}'s own scanner" if setup != 1 else "its own scanner"
        out.done.append(f"epoch {label}: {what} ({doc.get('name', '?')}) set again from the journal")


def _damaged_inputs(c: Campaign, out: RepairReport) -> None:
    """Put damaged input rows right from what else holds them: an epoch's date from the journal, a limit from the log.

    The others (reflectors, the campaign's settings and scanner) are held nowhere else: left, with the reason.
    """
    for table, key in c.damaged_inputs():
        what = describe_input(table, key)
        if table == "epochs":
            scans = [e for e in journal.entries(c.folder) if e.get("kind") == "scan" and e.get("epoch") == key
                     and e.get("epoch_datetime")]
            if scans:
                e = scans[0]
                with c.transaction() as conn:
                    conn.execute("UPDATE epochs SET datetime = ?, notes = ? WHERE label = ?",
                                 (e["epoch_datetime"], e.get("epoch_notes", ""), key))
                    digests.seal_row(conn, "epochs", key)
                    c.log_action(conn, "repair", key, {"damaged": "epochs", "datetime": e["epoch_datetime"]})
                out.done.append(f"{what}: damaged; its date ({e['epoch_datetime']}) and notes set again from the "
                                "journal of imports")
                continue
        if table == "limits":
            rules = [json.loads(r[0]) for r in c.conn.execute("SELECT details FROM log WHERE action = 'limit' "
                                                              "ORDER BY id")]
            rule = next((d["rule"] for d in reversed(rules) if d.get("reflector") == key and d.get("rule")), None)
            if rule is not None:
                c.set_limit(key, rule)
                out.done.append(f"{what}: damaged; set again from the campaign's log ({rule})")
                continue
        if table == "field_models":
            out.done.append(f"{what}: damaged; 'process' fits it again")
            continue
        out.left.append(damaged_input_line(c.folder, table, key))


def repair_campaign(c: Campaign, reimporters: Mapping[str, Reimporter] | None = None) -> RepairReport:
    """Register again what the database lost, read damaged series again (see the module notes)."""
    reimporters = reimporters or {}
    out = RepairReport()
    _damaged_inputs(c, out)
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
    out.done += repair_archived(c)  # scans the journal has archived: not lost, where it says
    _damaged_series(c, entries, reimporters, out)
    _visit_links(c, out)
    return out


def _visit_links(c: Campaign, out: RepairReport) -> None:
    """Link every registered scan under its own name in its visit's folder.

    For a campaign made before there were such links, or one whose links were removed.
    """
    d = c.folder / SCANS_DIR / BY_VISIT

    def count() -> int:
        return sum(1 for p in d.rglob("*") if p.is_symlink()) if d.is_dir() else 0

    n = count()
    for e in c.epochs():
        for f in c.files(e.label, setup=None):
            if not (c.folder / f.stored_path).is_file():
                continue  # archived out of the folder (or lost): no link to nothing
            link_by_visit(c.folder, f.stored_path, e.label, visit_link_name(f.role, f.setup, Path(f.original_path).name))
    made = count() - n
    if made:
        out.done.append(f"{made} scan(s) linked under the names they were imported with, in {SCANS_DIR}/{BY_VISIT}/")

"""Checking a campaign end to end: the database, every imported file, every stored result.

:func:`verify_store` runs the store's own checks and returns one :class:`Finding` per problem,
each a line saying what is wrong and what to do:

* the database: ``PRAGMA integrity_check`` and ``foreign_key_check``;
* every imported file (scans, camera and environment series, predictions) against the checksum
  recorded at its import: missing or changed files are to be imported again; a scan archived out of the
  folder (:mod:`projects.store.archive`) is checked at its place when that is reachable, and named as
  archived and not checked when it is not (a note, kind ``archived``: not a problem);
* files in the import folders that the database does not list (an older database restored over a
  newer folder): ``bridgesurvey repair`` registers them again;
* every stored result against the digest stored with it (:mod:`projects.store.digests`): damaged
  results are stale, recomputed by ``process`` (or by the command that made them).

Whether the results still match their inputs (stale after a new scan or parameter) is processing's
question; ``bridgesurvey verify`` adds it (see :mod:`app.cli.commands_store`).
"""
from __future__ import annotations

from dataclasses import dataclass

from common.files import sha256_of, stale_temp_files
from common.progress import ProgressCallback, report
from projects.store import digests, journal
from projects.store.archive import archived_from_journal, archived_scans, copy_state
from projects.store.campaign import DB_NAME, INPUT_REMEDY, Campaign, describe_input

#: What to do about a damaged result, by the table it is kept in.
REMEDY = {
    "plans": "run 'bridgesurvey process' to plan the epoch again",
    "map_previews": "run 'bridgesurvey process' to plan the epoch again",
    "epoch_results": "run 'bridgesurvey process' to measure the epoch again",
    "displacement_sets": "run 'bridgesurvey process' to compute its displacements again",
    "camera_series": "run 'bridgesurvey repair' to read it again from its imported file",
    "env_series": "run 'bridgesurvey repair' to read it again from its imported file",
    "predictions": "run 'bridgesurvey repair' to read it again from its imported file",
    "crossvals": "run 'bridgesurvey camera crossval' again",
    "comparisons": "run 'bridgesurvey compare' again",
    "setup_plans": "run 'bridgesurvey process' to plan the set-up again",
    "setup_previews": "run 'bridgesurvey process' to plan the set-up again",
    "setup_results": "run 'bridgesurvey process' to measure the set-up again",
}


@dataclass(frozen=True)
class Finding:
    """One problem found: what it concerns, what is wrong, what to do."""

    kind: str  # database, absent, changed, unlisted, damaged, stale; archived (a note, see NOTES)
    subject: str
    problem: str
    action: str

    def line(self) -> str:
        """The finding as one line for the user."""
        return f"{self.subject}: {self.problem}; {self.action}"

    @property
    def is_note(self) -> bool:
        """Whether it only informs (an archived scan not reachable now), rather than asks for a remedy."""
        return self.kind in NOTES


#: Kinds of findings that are notes, not problems: ``verify`` names them and still passes.
NOTES = frozenset({"archived"})


def _database(c: Campaign) -> list[Finding]:
    rows = [r[0] for r in c.conn.execute("PRAGMA integrity_check(20)")]
    out = []
    if rows != ["ok"]:
        out.append(Finding("database", DB_NAME, f"integrity_check reports {len(rows)} problem(s), first: {rows[0]}",
                           "restore campaign.sqlite from a backup (then run 'bridgesurvey repair')"))
    fk = c.conn.execute("PRAGMA foreign_key_check").fetchall()
    if fk:
        out.append(Finding("database", DB_NAME, f"{len(fk)} row(s) refer to rows that do not exist (first in table "
                           f"{fk[0][0]})", "restore campaign.sqlite from a backup"))
    return out


def imported_files(c: Campaign) -> list[tuple[str, str, str]]:
    """(stored path, sha256, original path) of every file the database lists, each once."""
    seen: dict[str, tuple[str, str, str]] = {}
    for table in ("files", "camera_series", "env_series", "predictions"):
        for r in c.conn.execute(f"SELECT stored_path, sha256, original_path FROM {table} ORDER BY stored_path"):
            seen.setdefault(r[0], (r[0], r[1], r[2]))
    return list(seen.values())


def _files(c: Campaign, progress: ProgressCallback | None) -> list[Finding]:
    out = []
    files = imported_files(c)
    archived = {a.file.stored_path: a for a in archived_scans(c)}
    journaled: dict[str, str] | None = None  # read when a file is missing
    for k, (rel, sha, original) in enumerate(files):
        report(progress, 0.1 + 0.8 * k / max(len(files), 1), f"checking {rel}")
        path = c.folder / rel
        a = archived.get(rel)
        if a is not None and not path.is_file():  # archived: checked where it is
            state = copy_state(a)
            if state == "changed":
                out.append(Finding("changed", rel, f"its archived copy {a.place} changed since its import (its "
                                   "checksum differs)", f"restore that copy from a backup, or import it again from "
                                   f"{original}"))
            elif state == "unreachable":
                out.append(Finding("archived", rel, f"archived to {a.place}, which is not reachable now: not checked",
                                   "connect the archive disk to check it ('bridgesurvey archive DIR --restore' "
                                   "brings it back)"))
            continue
        if not path.is_file():
            if journaled is None:
                journaled = {sha: place for sha, place, _ in archived_from_journal(c)}
            if sha in journaled:  # a database older than the archive run: the scan is not lost
                out.append(Finding("absent", rel, f"missing from the campaign folder, and the journal of imports has "
                                   f"it archived to {journaled[sha]}", "run 'bridgesurvey repair' to record it as "
                                   "archived again"))
                continue
            out.append(Finding("absent", rel, "missing from the campaign folder",
                               f"import it again from {original} (or restore it from a backup)"))
        elif sha256_of(path) != sha:
            out.append(Finding("changed", rel, "changed since its import (its checksum differs)",
                               f"restore it from a backup or import it again from {original}"))
    return out


def _unlisted(c: Campaign) -> list[Finding]:
    entries = journal.latest_by_path(c.folder)
    out = []
    for rel in c.unlisted_files():
        e = entries.get(rel)
        if e is None:
            out.append(Finding("unlisted", rel, "not listed by the database, and not in the journal of imports",
                               "import it again if it belongs to the campaign (it is never deleted)"))
            continue
        what = (f"the {e.get('role', '')} scan of epoch {e.get('epoch')}" if e.get("kind") == "scan"
                else f"{e.get('kind', 'a file')} {e.get('name') or ''}".strip())
        out.append(Finding("unlisted", rel, f"not listed by the database (an older campaign.sqlite restored?); the "
                           f"journal has it as {what}", "run 'bridgesurvey repair' to register it again"))
    return out


def describe_group(table: str, key: tuple) -> str:
    """A stored result group for a message ("displacements of epoch 2026-03-09", "camera series cam")."""
    group = digests.GROUPS[table]
    if group.key == ("epoch",):
        return f"{group.name} of epoch {key[0]}"
    if group.key == ("epoch", "setup"):
        return f"{group.name} of epoch {key[0]}, set-up {key[1]}"
    return f"{group.name} {' '.join(str(k) for k in key)}"


def _results(c: Campaign) -> list[Finding]:
    return [Finding("damaged", describe_group(table, key), "damaged (it does not match the checksum stored with "
                    "it); it is treated as stale and never shown", REMEDY[table])
            for table, key in c.damaged_results()]


def _inputs(c: Campaign) -> list[Finding]:
    return [Finding("damaged", describe_input(table, key), "damaged (its values do not match the checksum stored with "
                    "them); every command that would use it stops with one line",
                    INPUT_REMEDY[table].replace("DIR", str(c.folder)).replace("REFLECTOR", str(key)))
            for table, key in c.damaged_inputs()]


def _temporary(c: Campaign) -> list[Finding]:
    return [Finding("temporary", p.name, "a temporary file a killed command left", "the next writing command on the "
                    "campaign removes it (or delete it)") for p in stale_temp_files(c.folder)]


def verify_store(c: Campaign, *, progress: ProgressCallback | None = None) -> list[Finding]:
    """Every problem of the campaign's database, imported files and stored results (see the module notes)."""
    report(progress, 0.0, "checking the database")
    out = _database(c)
    out += _files(c, progress)
    report(progress, 0.9, "checking the stored results")
    out += _unlisted(c)
    out += _inputs(c)
    out += _temporary(c)
    out += _results(c)
    report(progress, 1.0, "checked")
    return out

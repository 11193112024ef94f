"""Visits with several set-ups, and scans read through a scanner pose: what the store keeps for them.

A visit (an epoch) may have several set-ups: the scanner stood at two or more stations, each with its own
scanner frame, coarse scan, plan and fine scans (``add-setup``). Set-up 1 is what the core tables hold, so a
campaign of one set-up a visit reads exactly as before; further set-ups live beside them, keyed by
(epoch, set-up), written in the same kind of transactions and sealed by their own digests:

* ``files.setup`` - the set-up a scan file belongs to (1 by default);
* ``files.frame`` - JSON, set-up number -> :class:`lidar.io.poses.FileFrame`: which of the file's scans belong
  to which set-up (an E57 of several scan positions) and the scanner pose that carries points exported in a
  project frame into the scanner's (NULL: one set-up, points in the scanner frame as stored);
* ``setup_plans``, ``setup_previews`` - the plan and map preview of set-ups 2, 3...;
* ``setup_results`` - their stage-1 result: stage, input hash and centroids (JSON of
  :func:`projects.store.field_tables.centroid_to_json`, closures alike).

How the set-ups of a visit were joined (the joint frame's residuals) is part of the epoch's displacements
(``displacement_set_extras``).
"""
from __future__ import annotations

import json
import sqlite3
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

from common.errors import InputError
from lidar.centroid import TargetCentroid
from lidar.io.poses import FileFrame, same_pose
from projects.store.field_tables import centroid_from_json, centroid_to_json

SCHEMA = """
ALTER TABLE files ADD COLUMN setup INTEGER NOT NULL DEFAULT 1;
ALTER TABLE files ADD COLUMN frame TEXT;
CREATE TABLE setup_plans (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    setup INTEGER NOT NULL CHECK (setup >= 2),
    json TEXT NOT NULL,
    inputs_hash TEXT NOT NULL,
    created TEXT NOT NULL,
    digest TEXT,
    PRIMARY KEY (epoch, setup)
);
CREATE TABLE setup_previews (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    setup INTEGER NOT NULL CHECK (setup >= 2),
    inputs_hash TEXT NOT NULL,
    arrays BLOB NOT NULL,
    annotations TEXT NOT NULL,
    digest TEXT,
    PRIMARY KEY (epoch, setup)
);
CREATE TABLE setup_results (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    setup INTEGER NOT NULL CHECK (setup >= 2),
    stage TEXT NOT NULL CHECK (stage IN ('planned', 'measured')),
    inputs_hash TEXT NOT NULL,
    processed TEXT NOT NULL,
    centroids TEXT NOT NULL,            -- JSON list of centroids (projects.store.field_tables.centroid_to_json)
    closures TEXT NOT NULL,             -- JSON list of closure centroids
    time_source TEXT,
    digest TEXT,
    PRIMARY KEY (epoch, setup)
);
"""

#: The digest groups of the set-up tables: (name, table, queries), keyed by (epoch, setup).
GROUPS = (
    ("set-up plan", "setup_plans",
     ("SELECT epoch, setup, json, inputs_hash, created FROM setup_plans WHERE epoch = ? AND setup = ?",)),
    ("set-up map preview", "setup_previews",
     ("SELECT epoch, setup, inputs_hash, arrays, annotations FROM setup_previews WHERE epoch = ? AND setup = ?",)),
    ("set-up centroids", "setup_results",
     ("SELECT epoch, setup, stage, inputs_hash, processed, centroids, closures, time_source FROM setup_results "
      "WHERE epoch = ? AND setup = ?",)),
)


def frames_to_json(frames: Mapping[int, FileFrame] | None) -> str | None:
    """The ``files.frame`` text of a file's set-up frames (None when there is nothing to record)."""
    if not frames:
        return None
    return json.dumps({str(k): f.to_json() for k, f in sorted(frames.items())}, sort_keys=True)


def frames_from_json(text: str | None) -> dict[int, FileFrame]:
    """The inverse of :func:`frames_to_json` (empty for NULL)."""
    if not text:
        return {}
    return {int(k): FileFrame.from_json(v) for k, v in json.loads(text).items()}


def write_plan(conn: sqlite3.Connection, epoch: str, setup: int, plan_json: dict, inputs_hash: str, created: str,
               preview: tuple[bytes, str] | None) -> None:
    """Replace a set-up's plan (and preview), making its result 'planned' without centroids (caller's transaction)."""
    conn.execute("INSERT OR REPLACE INTO setup_plans(epoch, setup, json, inputs_hash, created) VALUES (?, ?, ?, ?, ?)",
                 (epoch, setup, json.dumps(plan_json), inputs_hash, created))
    if preview is not None:
        conn.execute("INSERT OR REPLACE INTO setup_previews(epoch, setup, inputs_hash, arrays, annotations) "
                     "VALUES (?, ?, ?, ?, ?)", (epoch, setup, inputs_hash, preview[0], preview[1]))
    conn.execute("INSERT OR REPLACE INTO setup_results(epoch, setup, stage, inputs_hash, processed, centroids, "
                 "closures, time_source) VALUES (?, ?, 'planned', ?, ?, '[]', '[]', NULL)",
                 (epoch, setup, inputs_hash, created))


def write_centroids(conn: sqlite3.Connection, epoch: str, setup: int, cents: Mapping[str, TargetCentroid],
                    closures: Mapping[str, TargetCentroid], inputs_hash: str, processed: str, time_source: str) -> None:
    """Replace a set-up's measured result (caller's transaction)."""
    conn.execute("INSERT OR REPLACE INTO setup_results(epoch, setup, stage, inputs_hash, processed, centroids, "
                 "closures, time_source) VALUES (?, ?, 'measured', ?, ?, ?, ?, ?)",
                 (epoch, setup, inputs_hash, processed,
                  json.dumps([centroid_to_json(c) for _, c in sorted(cents.items())]),
                  json.dumps([centroid_to_json(c) for _, c in sorted(closures.items())]), time_source))


def read_result(conn: sqlite3.Connection, epoch: str, setup: int) -> sqlite3.Row | None:
    """A set-up's result row (stage, inputs_hash, processed, centroids, closures, time_source), or None."""
    return conn.execute("SELECT * FROM setup_results WHERE epoch = ? AND setup = ?", (epoch, setup)).fetchone()


def centroids_of(row: sqlite3.Row | None, column: str = "centroids") -> dict[str, TargetCentroid]:
    """The centroids (or ``column="closures"``) of a set-up's result row, by target."""
    if row is None:
        return {}
    return {c.reflector: c for c in (centroid_from_json(d) for d in json.loads(row[column]))}


def _known_frames(existing: Sequence) -> dict[int, FileFrame]:
    """Set-up -> the frame its coarse scan recorded (a pose, maybe a carry), from an epoch's stored files."""
    out: dict[int, FileFrame] = {}
    for f in existing:
        if f.role == "coarse":
            for k, fr in f.frames.items():
                out.setdefault(k, fr)
            out.setdefault(f.setup, FileFrame())
    return out


def _match_pose(frame: FileFrame, known: Mapping[int, FileFrame]) -> int | None:
    """The set-up whose coarse scan carries the same own pose as ``frame`` (None without one)."""
    if frame.pose is None or frame.source != "file":
        return None
    for k, fr in sorted(known.items()):
        if fr.source == "file" and same_pose(fr.pose, frame.pose):
            return k
    return None


def place_files(epoch: str, items: Sequence[tuple[Path, str]], existing: Sequence, *, setup: int | None,
                frames_of: Callable | None = None, validate: Callable | None = None
                ) -> list[tuple[int, str | None]]:
    """Read the files about to be imported into an epoch and say where each goes: (set-up, ``files.frame`` text).

    A coarse file starts set-up ``setup`` (one set-up per scan position it holds, numbered on); a fine
    file goes to the set-up whose coarse scan has its scans' pose, else to ``setup``, else to the last
    set-up. ``frames_of(path, fallback)`` reads a file (see :meth:`projects.store.campaign.Campaign.import_files`);
    without it ``validate(path)`` does, and the file is one set-up read as it is.
    """
    known = _known_frames(existing)
    have = sorted(known) or [1]
    if setup is not None and setup not in have and not any(r == "coarse" for _, r in items):
        raise InputError(f"epoch {epoch} has no set-up {setup}; its set-ups are {', '.join(map(str, have))} "
                         "(add one with 'bridgesurvey add-setup')")
    next_coarse = setup if setup is not None else have[-1]
    out: list[tuple[int, str | None]] = []
    for path, role in items:
        target = next_coarse if role == "coarse" else (setup if setup is not None else max(known, default=1))
        fallback = known.get(target)
        if frames_of is not None:
            groups = list(frames_of(path, fallback if fallback is not None and fallback.carry else None))
        else:
            if validate is not None:
                validate(path)
            groups = [FileFrame()]
        frames: dict[int, FileFrame] = {}
        if role == "coarse":
            for g in groups:
                frames[next_coarse] = g
                known[next_coarse] = g
                next_coarse += 1
        elif len(groups) == 1:
            frames[_match_pose(groups[0], known) or target] = groups[0]
        else:
            for n, g in enumerate(groups, start=1):
                k = _match_pose(g, known)
                if k is None:
                    raise InputError(f"{path}: holds {len(groups)} scan positions, and the pose of the {_nth(n)} "
                                     f"matches none of epoch {epoch}'s set-ups' coarse scans; import it with the "
                                     "set-ups' coarse scans, or one scan position a file")
                frames[k] = g
        recorded = {k: g for k, g in frames.items() if g.scans is not None or g.pose is not None}
        out.append((min(frames), frames_to_json(recorded)))
    return out


def _nth(n: int) -> str:
    return {1: "first", 2: "second", 3: "third"}.get(n, f"{n}th")

"""Checksums stored with every result: each blob and each group of rows carries the digest of its values.

``pragma integrity_check`` sees a damaged page structure, not a changed value: eight bytes changed
inside a stored displacement, or a flipped bit in a compressed map preview, pass it. So every stored
result is written with a digest of its values (BLAKE2b, 128 bits, over a canonical encoding of the
rows as the database returns them), and checked when it is read: a result whose digest does not
match is treated as not there (stale, recomputed by ``process``), never served.

A *group* is what is written together: an epoch's plan, its map preview, its stage-1 result with its
centroids, its displacement set with the displacements and reference checks, a series' arrays, a
prediction, a cross-validation, a comparison. :data:`GROUPS` says where each digest is kept and which
rows it covers; :func:`group_digest` computes one from the database, :func:`seal` stores it.
"""
from __future__ import annotations

import functools
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass

from projects.store import setup_tables
from projects.store.checksums import digest_of, encode_row, value_digest


@dataclass(frozen=True)
class Group:
    """Where a group's digest lives and which rows it covers.

    Attributes
    ----------
    name : str
        What it is, for messages ("plan", "map preview", ...).
    table : str
        The table whose ``digest`` column holds it.
    key : tuple of str
        The key columns of that table that name one group.
    queries : tuple of str
        SELECTs (with one ``?`` per key column) whose rows, in order, the digest covers.
    """

    name: str
    table: str
    key: tuple[str, ...]
    queries: tuple[str, ...]


GROUPS: dict[str, Group] = {g.table: g for g in (
    Group("plan", "plans", ("epoch",), ("SELECT epoch, json, inputs_hash, created FROM plans WHERE epoch = ?",)),
    Group("map preview", "map_previews", ("epoch",),
          ("SELECT epoch, inputs_hash, arrays, annotations FROM map_previews WHERE epoch = ?",)),
    Group("centroids", "epoch_results", ("epoch",), (
        "SELECT epoch, stage, inputs_hash, processed FROM epoch_results WHERE epoch = ?",
        "SELECT epoch, reflector, found, x, y, z, cov, n, threshold, separability, sigma_range_m, flags, n_window "
        "FROM centroids WHERE epoch = ? ORDER BY reflector",
        "SELECT epoch, reflector, extra FROM centroid_extras WHERE epoch = ? ORDER BY reflector",
        "SELECT epoch, reflector, centroid FROM closure_centroids WHERE epoch = ? ORDER BY reflector")),
    Group("displacements", "displacement_sets", ("epoch",), (
        "SELECT epoch, baseline, inputs_hash, normal, reference_point, reference_ids, normal_mode, flags, processed "
        "FROM displacement_sets WHERE epoch = ?",
        "SELECT epoch, reflector, displacement_m, sigma_m, vertical_m, baseline_vertical_m, flags FROM displacements "
        "WHERE epoch = ? ORDER BY reflector",
        "SELECT epoch, reflector, median_change_m, max_change_m, moved, missing, suspect FROM reference_checks "
        "WHERE epoch = ? ORDER BY reflector",
        "SELECT epoch, reflector, extra FROM displacement_extras WHERE epoch = ? ORDER BY reflector",
        "SELECT epoch, extra FROM displacement_set_extras WHERE epoch = ?")),
    Group("camera series", "camera_series", ("name",), (
        "SELECT name, reflector, sha256, stored_path, options, summary, arrays FROM camera_series WHERE name = ?",)),
    Group("environment series", "env_series", ("name",), (
        "SELECT name, kind, sha256, stored_path, options, summary, arrays FROM env_series WHERE name = ?",)),
    Group("design prediction", "predictions", ("reflector",), (
        "SELECT reflector, sha256, stored_path, options, arrays FROM predictions WHERE reflector = ?",)),
    Group("cross-validation", "crossvals", ("series",), ("SELECT series, summary FROM crossvals WHERE series = ?",)),
    Group("comparison", "comparisons", ("from_epoch", "to_epoch", "method"), (
        "SELECT from_epoch, to_epoch, method, summary FROM comparisons "
        "WHERE from_epoch = ? AND to_epoch = ? AND method = ?",)),
    *(Group(name, table, ("epoch", "setup"), queries) for name, table, queries in setup_tables.GROUPS),
)}
#: The groups that are pictures (the map previews): no number is computed from them. The quick looks leave them out
#: (:meth:`projects.store.campaign.Campaign.damaged_results`); ``verify`` and ``process`` check them.
PICTURES = ("map_previews", "setup_previews")
#: The tables whose digests schema 10 introduced (the set-up tables came with schema 11, digests included).
V10_TABLES = ("plans", "map_previews", "epoch_results", "displacement_sets", "camera_series", "env_series",
              "predictions", "crossvals", "comparisons")


def group_digest(conn: sqlite3.Connection, table: str, key: Sequence) -> str:
    """The digest of one group (``table`` as in :data:`GROUPS`, ``key`` its key values) as stored now."""
    g = GROUPS[table]
    rows: list[Sequence] = []
    for q in g.queries:
        rows.append((q,))  # each query's rows are framed, so rows cannot move from one part to another
        rows.extend(tuple(r) for r in conn.execute(q, tuple(key)))
    return value_digest(rows)


def _where(g: Group) -> str:
    return " AND ".join(f"{k} = ?" for k in g.key)


def _whole_table(g: Group, q: str) -> str:
    """A group query over every group of its table, in key order: ``WHERE key = ?`` made ``ORDER BY key``.

    Each query's first columns are the group's key (checked), so its rows can be told apart by group.
    """
    where = f"WHERE {_where(g)}"
    head, found, tail = q.partition(where)
    if not found or not head.startswith(f"SELECT {', '.join(g.key)},"):
        raise ValueError(f"{g.table}: a group query that does not select and filter its key first: {q}")
    order = ", ".join(g.key) + (", " + tail.split("ORDER BY", 1)[1].strip() if "ORDER BY" in tail else "")
    return f"{head.rstrip()} ORDER BY {order}"


def sound_groups(conn: sqlite3.Connection, table: str) -> dict[tuple, bool]:
    """Whether each stored group of ``table`` matches its digest (key -> bool), read in one pass a query.

    The same digests as :func:`is_sound` asks one group at a time (a few queries a group: at 520 visits, thousands),
    from each query run once over the table. A group the pass finds changed is asked again on its own, so that
    only :func:`is_sound`'s own reading can call it damaged.
    """
    g = GROUPS[table]
    n = len(g.key)
    # each group's rows as they enter its digest: encoded as read, so a blob is kept as its length and CRC only
    parts: dict[tuple, list[bytes]] = {k: [] for k in keys_of(conn, table)}
    for q in g.queries:
        for k in parts:
            encode_row((q,), parts[k].append)
        for r in conn.execute(_whole_table(g, q)):
            row = tuple(r)
            got = parts.get(row[:n])
            if got is not None:  # a row of no group (an orphan) is in no group's digest either
                encode_row(row, got.append)
    stored = {row[:n]: row[n] for row in map(tuple, conn.execute(f"SELECT {', '.join(g.key)}, digest FROM {table}"))}
    return {k: (stored.get(k) is not None and stored[k] == digest_of(got)) or is_sound(conn, table, k)
            for k, got in parts.items()}


def seal(conn: sqlite3.Connection, table: str, key: Sequence) -> None:
    """Store the digest of a group just written (inside the transaction that wrote it)."""
    g = GROUPS[table]
    conn.execute(f"UPDATE {table} SET digest = ? WHERE {_where(g)}", (group_digest(conn, table, key), *key))


def stored_digest(conn: sqlite3.Connection, table: str, key: Sequence) -> str | None:
    """The digest stored with a group (None when the group does not exist or has none)."""
    g = GROUPS[table]
    row = conn.execute(f"SELECT digest FROM {table} WHERE {_where(g)}", tuple(key)).fetchone()
    return None if row is None else row[0]


def is_sound(conn: sqlite3.Connection, table: str, key: Sequence) -> bool:
    """Whether a stored group still has the digest it was written with (False for a missing digest too)."""
    stored = stored_digest(conn, table, key)
    return stored is not None and stored == group_digest(conn, table, key)


def keys_of(conn: sqlite3.Connection, table: str) -> list[tuple]:
    """The keys of every group stored in ``table``."""
    g = GROUPS[table]
    return [tuple(r) for r in conn.execute(f"SELECT {', '.join(g.key)} FROM {table} ORDER BY {', '.join(g.key)}")]


def damaged(conn: sqlite3.Connection, table: str) -> list[tuple]:
    """Keys of the groups of ``table`` whose digest does not match their values."""
    return [k for k in keys_of(conn, table) if not is_sound(conn, table, k)]


def seal_all(conn: sqlite3.Connection, tables: Sequence[str] | None = None) -> None:
    """Store the digest of every group of ``tables`` (default all; the migration that introduced digests)."""
    for table in (GROUPS if tables is None else tables):
        for key in keys_of(conn, table):
            seal(conn, table, key)


# ---------------------------------------------------------------------------------------------- input rows
@dataclass(frozen=True)
class RowGroup:
    """An input row every number depends on, whose digest is kept beside its values (schema 12).

    Unlike a result (recomputed when it fails its digest) an input cannot be recomputed: a damaged
    one is named in one line by every command that would use it, and by ``verify``.

    Attributes
    ----------
    name : str
        What a row is, for messages ("limit", "epoch", ...).
    table : str
        Its table.
    key : str
        The column naming one row.
    columns : tuple of str
        The columns the digest covers, in order.
    column : str
        The column holding the digest.
    """

    name: str
    table: str
    key: str
    columns: tuple[str, ...]
    column: str = "digest"


INPUTS: dict[str, RowGroup] = {g.table: g for g in (
    RowGroup("campaign setting", "meta", "key", ("key", "value")),
    RowGroup("reflector", "reflectors", "id", ("id", "grp", "x", "y", "z", "diameter_m", "installed", "retired",
                                                "replaces", "note", "nx", "ny", "nz")),
    RowGroup("epoch", "epochs", "label", ("label", "datetime", "notes", "created")),
    RowGroup("limit", "limits", "reflector", ("reflector", "warning_mm", "alarm_mm", "rule")),
    RowGroup("field model", "field_models", "id", ("id", "model", "digest", "created"), column="row_digest"),
)}
#: Rows of ``meta`` that are not sealed: the schema version, which migrations and ``repair`` write.
UNSEALED_META = frozenset({"schema_version"})


def row_digest(table: str, row: sqlite3.Row | Sequence) -> str:
    """The digest of one input row of ``table`` (a ``sqlite3.Row`` with the group's columns, or their values)."""
    g = INPUTS[table]
    values = tuple(row[c] for c in g.columns) if isinstance(row, sqlite3.Row) else tuple(row)
    return value_digest([(g.table,), values])


def row_is_sound(table: str, row: sqlite3.Row) -> bool:
    """Whether an input row (read with its digest column) still has the digest it was written with."""
    g = INPUTS[table]
    if table == "meta" and row["key"] in UNSEALED_META:
        return True
    stored = row[g.column]
    return stored is not None and _matches(table, tuple(row[c] for c in g.columns), stored)


@functools.lru_cache(maxsize=1 << 16)
def _matches(table: str, values: tuple, stored: str) -> bool:
    """Whether ``values`` (an input row of ``table``) have the digest ``stored``.

    A pure function of its arguments, so remembered: ``status`` and the application's opening check the same
    settings and reflector rows once a visit (at 520 visits, 11,000 digests of 21 rows).
    """
    return stored == row_digest(table, values)


def seal_row(conn: sqlite3.Connection, table: str, key) -> None:
    """Store the digest of one input row just written (inside the transaction that wrote it)."""
    g = INPUTS[table]
    row = conn.execute(f"SELECT {', '.join(g.columns)} FROM {table} WHERE {g.key} = ?", (key,)).fetchone()
    if row is not None:
        conn.execute(f"UPDATE {table} SET {g.column} = ? WHERE {g.key} = ?", (row_digest(table, tuple(row)), key))


def seal_rows(conn: sqlite3.Connection, table: str) -> None:
    """Store the digest of every row of an input table (creating a campaign; the migration that brought them)."""
    g = INPUTS[table]
    for (key,) in conn.execute(f"SELECT {g.key} FROM {table}").fetchall():
        if not (table == "meta" and key in UNSEALED_META):
            seal_row(conn, table, key)


def damaged_rows(conn: sqlite3.Connection, table: str) -> list:
    """The keys of the rows of an input table whose digest does not match their values."""
    g = INPUTS[table]
    rows = conn.execute(f"SELECT {', '.join(g.columns)}, {g.column} FROM {table} ORDER BY {g.key}").fetchall()
    return [r[g.key] for r in rows if not row_is_sound(table, r)]

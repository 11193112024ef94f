"""The campaign database schema, its version and the migrations from older versions.

A campaign records its schema version in ``meta.schema_version``. Opening one checks that the
version is a number this BridgeSurvey knows and that the tables agree with it (a version that says
6 over the tables of 8 is damage, not an old campaign); each migration then runs in one transaction
with the new version number, so a failed or interrupted upgrade leaves the campaign as it was.
"""
from __future__ import annotations

import functools
import sqlite3
from collections.abc import Callable

from common.flags import RENAMED
from projects.store import digests
from projects.store.errors import CampaignError
from projects.store.field_tables import SCHEMA as FIELD_SCHEMA
from projects.store.setup_tables import SCHEMA as SETUP_SCHEMA

SCHEMA_VERSION = 13

SCHEMA_V1 = """
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE reflectors (
    id TEXT PRIMARY KEY,
    grp TEXT NOT NULL CHECK (grp IN ('reference', 'measurement')),
    x REAL NOT NULL, y REAL NOT NULL, z REAL NOT NULL,
    diameter_m REAL NOT NULL CHECK (diameter_m > 0),
    installed TEXT,                     -- ISO date-time from which it is expected in scans (NULL: from the start)
    retired TEXT,                       -- ISO date-time after which it is no longer expected
    replaces TEXT REFERENCES reflectors(id),
    note TEXT NOT NULL DEFAULT ''
);
CREATE TABLE epochs (
    label TEXT PRIMARY KEY,
    datetime TEXT NOT NULL,
    notes TEXT NOT NULL DEFAULT '',
    created TEXT NOT NULL
);
CREATE TABLE files (
    sha256 TEXT PRIMARY KEY,
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    role TEXT NOT NULL CHECK (role IN ('coarse', 'fine')),
    stored_path TEXT NOT NULL UNIQUE,
    original_path TEXT NOT NULL,
    size INTEGER NOT NULL,
    imported TEXT NOT NULL
);
CREATE TABLE plans (
    epoch TEXT PRIMARY KEY REFERENCES epochs(label) ON DELETE CASCADE,
    json TEXT NOT NULL,
    inputs_hash TEXT NOT NULL,
    created TEXT NOT NULL
);
CREATE TABLE centroids (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    reflector TEXT NOT NULL REFERENCES reflectors(id),
    found INTEGER NOT NULL,
    x REAL, y REAL, z REAL,
    cov TEXT NOT NULL,
    n INTEGER NOT NULL,
    threshold REAL, separability REAL, sigma_range_m REAL,
    flags TEXT NOT NULL,
    PRIMARY KEY (epoch, reflector)
);
CREATE TABLE epoch_results (
    epoch TEXT PRIMARY KEY REFERENCES epochs(label) ON DELETE CASCADE,
    stage TEXT NOT NULL CHECK (stage IN ('planned', 'measured')),
    inputs_hash TEXT NOT NULL,
    processed TEXT NOT NULL
);
CREATE TABLE displacement_sets (
    epoch TEXT PRIMARY KEY REFERENCES epochs(label) ON DELETE CASCADE,
    baseline TEXT NOT NULL REFERENCES epochs(label),
    inputs_hash TEXT NOT NULL,
    normal TEXT NOT NULL, reference_point TEXT NOT NULL, reference_ids TEXT NOT NULL,
    normal_mode TEXT NOT NULL, flags TEXT NOT NULL,
    processed TEXT NOT NULL
);
CREATE TABLE displacements (
    epoch TEXT NOT NULL REFERENCES displacement_sets(epoch) ON DELETE CASCADE,
    reflector TEXT NOT NULL REFERENCES reflectors(id),
    displacement_m REAL, sigma_m REAL, vertical_m REAL, baseline_vertical_m REAL,
    flags TEXT NOT NULL,
    PRIMARY KEY (epoch, reflector)
);
CREATE TABLE reference_checks (
    epoch TEXT NOT NULL REFERENCES displacement_sets(epoch) ON DELETE CASCADE,
    reflector TEXT NOT NULL REFERENCES reflectors(id),
    median_change_m REAL, max_change_m REAL, moved INTEGER NOT NULL, missing INTEGER NOT NULL,
    suspect INTEGER NOT NULL,
    PRIMARY KEY (epoch, reflector)
);
CREATE TABLE limits (
    reflector TEXT PRIMARY KEY,         -- '*' holds the default for every measurement target
    warning_mm REAL, alarm_mm REAL, rule TEXT NOT NULL
);
CREATE TABLE log (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    time TEXT NOT NULL, action TEXT NOT NULL, epoch TEXT, details TEXT NOT NULL
);
CREATE INDEX files_by_epoch ON files(epoch);
"""


def _add_digests(conn: sqlite3.Connection) -> None:
    """Migration 10: a digest column on every table of results, filled for what is stored already."""
    for table in digests.V10_TABLES:
        conn.execute(f"ALTER TABLE {table} ADD COLUMN digest TEXT")
    digests.seal_all(conn, digests.V10_TABLES)


def _add_row_digests(conn: sqlite3.Connection) -> None:
    """Migration 12: a digest beside every input row (limits, epochs, reflectors, settings, the field model)."""
    for g in digests.INPUTS.values():
        conn.execute(f"ALTER TABLE {g.table} ADD COLUMN {g.column} TEXT")
        digests.seal_rows(conn, g.table)


Migration = str | Callable[[sqlite3.Connection], None]

# version -> SQL (or a function) that upgrades the previous version to it. A new campaign is created
# as version 1 and then upgraded through every migration, so new and migrated campaigns have the same schema.
MIGRATIONS: dict[int, Migration] = {
    # 2: what the report needs to show each epoch without re-reading its scans: a reduced reflectance
    #    map with its detections, and the points each fine-scan window actually held.
    2: """
    ALTER TABLE centroids ADD COLUMN n_window INTEGER;
    CREATE TABLE map_previews (
        epoch TEXT PRIMARY KEY REFERENCES epochs(label) ON DELETE CASCADE,
        inputs_hash TEXT NOT NULL,
        arrays BLOB NOT NULL,           -- numpy .npz: reduced map arrays and geometry
        annotations TEXT NOT NULL       -- JSON: detections and identified reflectors
    );
    """,
    # 3: whole-scan comparisons of two epochs (registration, change statistics, span profile) for reports.
    3: """
    CREATE TABLE comparisons (
        from_epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
        to_epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
        method TEXT NOT NULL,
        summary TEXT NOT NULL,          -- JSON, see projects.compare.whole_scan
        created TEXT NOT NULL,
        PRIMARY KEY (from_epoch, to_epoch, method)
    );
    """,
    # 4: displacement series of a dual-camera installation and their cross-validation with LiDAR.
    4: """
    CREATE TABLE camera_series (
        name TEXT PRIMARY KEY,
        reflector TEXT REFERENCES reflectors(id),   -- the LiDAR target the camera watches
        sha256 TEXT NOT NULL UNIQUE,
        stored_path TEXT NOT NULL UNIQUE,           -- the imported file, copied read-only into camera/
        original_path TEXT NOT NULL,
        imported TEXT NOT NULL,
        options TEXT NOT NULL,                      -- JSON: how the file was read (column, unit, zone, sign)
        summary TEXT NOT NULL,                      -- JSON: rows, period, sampling, gaps, bad rows
        arrays BLOB NOT NULL                        -- numpy .npz: time_ns (UTC), value_mm (positive up)
    );
    CREATE TABLE crossvals (
        series TEXT PRIMARY KEY REFERENCES camera_series(name) ON DELETE CASCADE,
        summary TEXT NOT NULL,                      -- JSON, see vision.crossval.CrossValidation
        created TEXT NOT NULL
    );
    """,
    # 5: target normals from layout.csv (nx,ny,nz; NULL when the layout gives none), for planning.
    5: """
    ALTER TABLE reflectors ADD COLUMN nx REAL;
    ALTER TABLE reflectors ADD COLUMN ny REAL;
    ALTER TABLE reflectors ADD COLUMN nz REAL;
    """,
    # 6: what explains the displacements: environment series (temperature, sun, rain...) and events
    #    (construction steps, loads, repairs).
    6: """
    CREATE TABLE env_series (
        name TEXT PRIMARY KEY,
        kind TEXT NOT NULL,                         -- temperature, structure-temperature, solar, rain, snow, humidity
        sha256 TEXT NOT NULL UNIQUE,
        stored_path TEXT NOT NULL UNIQUE,           -- the imported file, copied read-only into environment/
        original_path TEXT NOT NULL,
        imported TEXT NOT NULL,
        options TEXT NOT NULL,                      -- JSON: column, unit, zone
        summary TEXT NOT NULL,                      -- JSON: rows, period, sampling, gaps, bad rows
        arrays BLOB NOT NULL                        -- numpy .npz: time_ns (UTC), values in the kind's unit
    );
    CREATE TABLE events (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        date TEXT NOT NULL,                         -- ISO 8601 UTC
        kind TEXT NOT NULL CHECK (kind IN ('construction', 'load', 'repair', 'other')),
        label TEXT NOT NULL,
        load_kn_m REAL,
        created TEXT NOT NULL
    );
    """,
    # 7: the design (finite-element) prediction of each target's displacement, aligned to the measurements.
    7: """
    CREATE TABLE predictions (
        reflector TEXT PRIMARY KEY REFERENCES reflectors(id),
        sha256 TEXT NOT NULL,                       -- the file (one file may hold every target)
        stored_path TEXT NOT NULL,
        original_path TEXT NOT NULL,
        imported TEXT NOT NULL,
        options TEXT NOT NULL,                      -- JSON: alignment (date or lsq), offset_mm, axis (date/age)
        arrays BLOB NOT NULL                        -- numpy .npz: time_ns (UTC), value_mm (positive up, unaligned)
    );
    """,
    # 8: flag codes are snake_case everywhere (common.flags): the camera cross-check's kebab-case codes of
    #    older versions are renamed in the stored summaries (common.flags.RENAMED).
    8: "".join(f"""UPDATE crossvals SET summary = replace(summary, '"{old}"', '"{new}"');\n"""
               for old, new in RENAMED.items()),
    # 9: the field error budget: centroid times and incidences, closure centroids, along-span movements and
    #    budgets, each epoch's scale and drift, and the campaign's field model (projects.store.field_tables).
    9: FIELD_SCHEMA,
    # 10: every stored result carries the digest of its values (projects.store.digests), so damage that
    #     passes integrity_check is found by 'verify' and the result recomputed instead of served.
    10: _add_digests,
    # 11: visits with several set-ups (each file's set-up, the plans, map previews and centroids of set-ups 2, 3...)
    #     and scans read through a scanner pose (each file's frame) (projects.store.setup_tables).
    11: SETUP_SCHEMA,
    # 12: every input row a number depends on (limits, epochs with their dates, reflectors, the scanner profiles
    #     and settings in meta, the field model) carries the digest of its values (projects.store.digests.INPUTS),
    #     so a changed alarm limit or epoch date is named, never served.
    12: _add_row_digests,
    # 13: scans moved out of the campaign folder once their visit was processed (projects.store.archive): where
    #     each copy went, checked against the scan's checksum at its import. The files row stays as it was.
    13: """
    CREATE TABLE archived_files (
        sha256 TEXT PRIMARY KEY REFERENCES files(sha256) ON DELETE CASCADE,
        place TEXT NOT NULL,                        -- absolute path of the checked copy outside the campaign
        archived TEXT NOT NULL                      -- when the copy was checked and recorded (ISO 8601 UTC)
    );
    """,
}

#: What each migration leaves that can be seen in the tables: version -> (table, column or None).
#: Version 8 renames codes inside stored documents only and leaves no mark.
MARKS: dict[int, tuple[str, str | None]] = {
    1: ("displacements", None), 2: ("map_previews", None), 3: ("comparisons", None), 4: ("camera_series", None),
    5: ("reflectors", "nx"), 6: ("env_series", None), 7: ("predictions", None), 9: ("field_models", None),
    10: ("plans", "digest"), 11: ("setup_plans", None), 12: ("limits", "digest"),
    13: ("archived_files", None),
}


def _statements(script: str) -> list[str]:
    """The SQL statements of a script, one by one (``executescript`` would commit the transaction)."""
    out, buf = [], ""
    for line in script.splitlines(keepends=True):
        buf += line
        if sqlite3.complete_statement(buf):
            if buf.strip():
                out.append(buf.strip())
            buf = ""
    if buf.strip():
        out.append(buf.strip())
    return out


def _apply(conn: sqlite3.Connection, step: Migration) -> None:
    if callable(step):
        step(conn)
    else:
        for stmt in _statements(step):
            conn.execute(stmt)


def create(conn: sqlite3.Connection) -> None:
    """Create a new campaign database in one transaction: version 1 and every migration after it."""
    conn.execute("BEGIN")
    try:
        _apply(conn, SCHEMA_V1)
        conn.execute("INSERT INTO meta(key, value) VALUES ('schema_version', '1')")
        for v in range(2, SCHEMA_VERSION + 1):
            _apply(conn, MIGRATIONS[v])
        conn.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),))
    except BaseException:
        conn.rollback()
        raise
    conn.commit()


def _has(conn: sqlite3.Connection, table: str, column: str | None) -> bool:
    if not conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (table,)).fetchone():
        return False
    return column is None or any(r[1] == column for r in conn.execute(f"PRAGMA table_info({table})"))


def structural_version(conn: sqlite3.Connection) -> int:
    """The newest version whose tables the database holds, and every earlier one's (0: not a campaign's tables).

    A campaign of version 8 shows as 7 (version 8 leaves no mark in the tables).
    """
    found = 0
    for v in sorted(MARKS):
        if not _has(conn, *MARKS[v]):
            break
        found = v
    return found


def recorded_version(conn: sqlite3.Connection) -> str | None:
    """The text of ``meta.schema_version`` (None when the row or the table is missing)."""
    try:
        row = conn.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
    except sqlite3.OperationalError:
        return None
    return None if row is None else str(row[0])


@functools.lru_cache(maxsize=1)
def _reference() -> tuple[dict[str, tuple[str, ...]], dict[str, tuple[str, ...]]]:
    """The tables of a new campaign: table -> its columns, and table -> the SQL creating it (and its indexes)."""
    conn = sqlite3.connect(":memory:")
    try:
        create(conn)
        names = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE "
                                            "'sqlite_%' ORDER BY name")]
        columns = {t: tuple(r[1] for r in conn.execute(f"PRAGMA table_info({t})")) for t in names}
        sql = {t: tuple(r[0] for r in conn.execute("SELECT sql FROM sqlite_master WHERE tbl_name = ? AND sql IS NOT "
                                                   "NULL ORDER BY type DESC", (t,))) for t in names}
    finally:
        conn.close()
    return columns, sql


def creation_sql(table: str) -> tuple[str, ...]:
    """The statements that create ``table`` (and its indexes) as a new campaign of this version has it."""
    return _reference()[1][table]


def missing_parts(conn: sqlite3.Connection) -> list[str]:
    """The tables (``"limits"``) and columns (``"files.setup"``) of the current schema that a database lacks."""
    have = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    out = []
    for table, columns in _reference()[0].items():
        if table not in have:
            out.append(table)
            continue
        got = {r[1] for r in conn.execute(f"PRAGMA table_info({table})")}
        out += [f"{table}.{col}" for col in columns if col not in got]
    return out


def missing_tables_error(where: str, missing: list[str]) -> CampaignError:
    """The one line for a campaign database that lost tables or columns of its version (never an old campaign)."""
    what = ", ".join(missing)
    return CampaignError(f"{where}: campaign.sqlite is damaged: it lacks {'table' if len(missing) == 1 else 'tables'} "
                         f"{what}; run 'bridgesurvey repair {where}' (it makes again what can be recomputed or read "
                         "from the journal of imports, and says what it cannot), or restore campaign.sqlite from a "
                         "backup")


def check_tables(conn: sqlite3.Connection, where: str = "campaign") -> None:
    """Raise the one-line :class:`CampaignError` when a current campaign lacks a table or column of its schema."""
    missing = missing_parts(conn)
    if missing:
        raise missing_tables_error(where, missing)


def _has_meta(conn: sqlite3.Connection) -> bool:
    return conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'meta'").fetchone() is not None


def version_of(conn: sqlite3.Connection, where: str = "campaign") -> int:
    """The schema version of a campaign database, checked against its tables.

    A missing, unreadable or impossible version is a :class:`CampaignError` in one line naming
    ``where`` (the campaign folder). A version newer than this BridgeSurvey's is returned as it is
    (the caller refuses it).
    """
    if not _has_meta(conn) and structural_version(conn) > 0:
        raise CampaignError(f"{where}: campaign.sqlite is damaged: it lacks table meta (the campaign's name, schema "
                            "version, scanner and settings); BridgeSurvey cannot make it again: restore "
                            "campaign.sqlite from a backup")
    text = recorded_version(conn)
    hint = ("run 'bridgesurvey repair' on the campaign folder to set it from the tables, or restore "
            "campaign.sqlite from a backup")
    try:
        version = int(str(text).strip())
    except ValueError:
        version = -1
    if text is None or version < 1:
        what = "no schema version" if text is None else f"{text!r}"
        raise CampaignError(f"{where}: campaign.sqlite has an unreadable schema version ({what}); {hint}")
    if version > SCHEMA_VERSION:
        return version
    if version == SCHEMA_VERSION:  # the current version: a missing table is damage, named as such
        check_tables(conn, where)
        return version
    have = structural_version(conn)
    if have == 0:
        raise CampaignError(f"{where}: campaign.sqlite is not a campaign database (its tables are not a campaign's)")
    # every mark up to the version must be there, and none after it
    expected = max(v for v in MARKS if v <= version)
    if have != expected:
        raise CampaignError(f"{where}: campaign.sqlite has an unreadable schema version: it says {version} but its "
                            f"tables are those of version {have if have != 7 else '7 or 8'}; {hint}")
    return version


def inferred_version(conn: sqlite3.Connection) -> int:
    """The version to record for a database whose own record is damaged: what its tables show.

    Version 8 leaves no mark, so tables of 7 give 7 (migration 8 only renames, and does no harm
    when run again).
    """
    return structural_version(conn)


def migrate(conn: sqlite3.Connection, from_version: int, to_version: int | None = None) -> None:
    """Upgrade an older campaign in place to ``to_version`` (default the current), each version in one transaction.

    A migration that fails leaves the campaign at the version before it (a :class:`CampaignError`).
    """
    for v in range(from_version + 1, (SCHEMA_VERSION if to_version is None else to_version) + 1):
        conn.execute("BEGIN IMMEDIATE")
        try:
            _apply(conn, MIGRATIONS[v])
            conn.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(v),))
        except sqlite3.DatabaseError as exc:
            conn.rollback()
            raise CampaignError(f"the upgrade of the campaign from schema {v - 1} to {v} failed ({exc}); the "
                                f"campaign is unchanged at version {v - 1}") from None
        except BaseException:
            conn.rollback()
            raise
        conn.commit()

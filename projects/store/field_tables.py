"""What the field error budget keeps: centroid details, closure centroids, budgets and the campaign's field model.

The core tables (centroids, displacements, displacement sets) keep their columns; what the field
error budget adds lives beside them, keyed the same way and written in the same transactions:

* ``centroid_extras`` - each centroid's time, incidence, disc normal and clipped fraction (JSON);
* ``closure_centroids`` - the plan's closure windows: a target scanned again at the end of a visit;
* ``displacement_extras`` - each displacement's along-span movement and error budget (JSON);
* ``displacement_set_extras`` - each epoch's scale and drift as its displacements used them (JSON);
* ``field_models`` - the campaign's field model (:class:`lidar.systematic.adjustment.FieldModel`), JSON of
  :data:`lidar.systematic.adjustment.FIELD_MODEL_FORMAT_VERSION`, with its digest.
"""
from __future__ import annotations

import json
import sqlite3
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from lidar.centroid import TargetCentroid
from projects.store.checksums import value_digest

SCHEMA = """
CREATE TABLE centroid_extras (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    reflector TEXT NOT NULL,
    extra TEXT NOT NULL,                -- JSON: time_s, time_span_s, time_source, normal, clipped_fraction
    PRIMARY KEY (epoch, reflector)
);
CREATE TABLE closure_centroids (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    reflector TEXT NOT NULL,
    centroid TEXT NOT NULL,             -- JSON: the centroid (position, covariance, points, flags, time)
    PRIMARY KEY (epoch, reflector)
);
CREATE TABLE displacement_extras (
    epoch TEXT NOT NULL REFERENCES epochs(label) ON DELETE CASCADE,
    reflector TEXT NOT NULL,
    extra TEXT NOT NULL,                -- JSON: along_m, along_sigma_m, budget (m)
    PRIMARY KEY (epoch, reflector)
);
CREATE TABLE displacement_set_extras (
    epoch TEXT PRIMARY KEY REFERENCES epochs(label) ON DELETE CASCADE,
    extra TEXT NOT NULL                 -- JSON: scale_ppm, scale_sigma_ppm, drift, time source, model digest
);
CREATE TABLE field_models (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    model TEXT NOT NULL,                -- JSON, see projects.store.field_tables
    digest TEXT NOT NULL,
    created TEXT NOT NULL
);
"""


def _num(v: Any) -> float | None:
    f = float(v)
    return f if np.isfinite(f) else None


def _nan(v: Any) -> float:
    return float("nan") if v is None else float(v)


def centroid_extra(tc: TargetCentroid, time_source: str) -> dict:
    """The JSON of what the core centroid row does not hold."""
    return {"time_s": _num(tc.time_s), "time_span_s": _num(tc.time_span_s), "time_source": time_source,
            "normal": [_num(v) for v in np.asarray(tc.normal_socs, dtype=np.float64)],
            "clipped_fraction": _num(tc.clipped_fraction)}


def with_extra(tc: TargetCentroid, extra: dict | None) -> TargetCentroid:
    """A stored centroid with its extra details put back."""
    if not extra:
        return tc
    normal = np.array([_nan(v) for v in extra.get("normal") or [None] * 3], dtype=np.float64)
    return replace(tc, time_s=_nan(extra.get("time_s")), time_span_s=_nan(extra.get("time_span_s")),
                   normal_socs=normal, clipped_fraction=_nan(extra.get("clipped_fraction")) if
                   extra.get("clipped_fraction") is not None else 0.0)


def centroid_to_json(tc: TargetCentroid) -> dict:
    """A whole centroid as JSON (for the closure table)."""
    return {"reflector": tc.reflector, "xyz": [_num(v) for v in tc.xyz_socs],
            "cov": np.nan_to_num(tc.cov, nan=0.0).tolist(), "n": int(tc.n_points), "threshold": _num(tc.threshold),
            "separability": _num(tc.separability), "flags": list(tc.flags), "n_window": int(tc.n_window),
            "sigma_range_m": _num(tc.sigma_range_m), **centroid_extra(tc, "points")}


def centroid_from_json(d: dict) -> TargetCentroid:
    """The inverse of :func:`centroid_to_json`."""
    tc = TargetCentroid(d["reflector"], np.array([_nan(v) for v in d["xyz"]]), np.array(d["cov"], dtype=float),
                        int(d["n"]), _nan(d["threshold"]), _nan(d["separability"]), tuple(d["flags"]),
                        int(d["n_window"]), sigma_range_m=_nan(d["sigma_range_m"]))
    return with_extra(tc, d)


def write_centroid_extras(conn: sqlite3.Connection, epoch: str, cents: Mapping[str, TargetCentroid],
                          closures: Mapping[str, TargetCentroid], time_source: str) -> None:
    """Replace an epoch's centroid details and closure centroids (inside the caller's transaction)."""
    conn.execute("DELETE FROM centroid_extras WHERE epoch = ?", (epoch,))
    conn.execute("DELETE FROM closure_centroids WHERE epoch = ?", (epoch,))
    conn.executemany("INSERT INTO centroid_extras VALUES (?, ?, ?)",
                     [(epoch, rid, json.dumps(centroid_extra(tc, time_source))) for rid, tc in cents.items()])
    conn.executemany("INSERT INTO closure_centroids VALUES (?, ?, ?)",
                     [(epoch, rid, json.dumps(centroid_to_json(tc))) for rid, tc in closures.items()])


def read_centroid_extras(conn: sqlite3.Connection, epoch: str) -> dict[str, dict]:
    """Each reflector's details (JSON dict) in one epoch."""
    return {r[0]: json.loads(r[1]) for r in
            conn.execute("SELECT reflector, extra FROM centroid_extras WHERE epoch = ?", (epoch,))}


def read_closures(conn: sqlite3.Connection, epoch: str) -> dict[str, TargetCentroid]:
    """The closure centroids of one epoch (empty when its plan had none or the scans carry no times)."""
    return {r[0]: centroid_from_json(json.loads(r[1])) for r in
            conn.execute("SELECT reflector, centroid FROM closure_centroids WHERE epoch = ? ORDER BY reflector",
                         (epoch,))}


def write_displacement_extras(conn: sqlite3.Connection, epoch: str, res: Any, systematics: dict | None) -> None:
    """Each displacement's along-span movement and budget, and the epoch's systematics (caller's transaction)."""
    conn.execute("DELETE FROM displacement_extras WHERE epoch = ?", (epoch,))
    conn.execute("DELETE FROM displacement_set_extras WHERE epoch = ?", (epoch,))
    rows = []
    for d in res.displacements:
        extra = {"along_m": _num(d.along_m), "along_sigma_m": _num(d.along_sigma_m),
                 "budget": {k: _num(v) for k, v in dict(d.budget).items()}}
        rows.append((epoch, d.reflector, json.dumps(extra)))
    conn.executemany("INSERT INTO displacement_extras VALUES (?, ?, ?)", rows)
    if systematics is not None:
        conn.execute("INSERT INTO displacement_set_extras VALUES (?, ?)", (epoch, json.dumps(systematics)))


def read_set_extras(conn: sqlite3.Connection, epoch: str) -> dict:
    """The systematics an epoch's displacements were computed with (empty when none were stored)."""
    r = conn.execute("SELECT extra FROM displacement_set_extras WHERE epoch = ?", (epoch,)).fetchone()
    return {} if r is None else json.loads(r[0])


# ---------------------------------------------------------------------------------------------- field model
def write_field_model(conn: sqlite3.Connection, model_json: dict, digest: str, created: str) -> None:
    """Replace the stored field model (caller's transaction)."""
    conn.execute("INSERT OR REPLACE INTO field_models(id, model, digest, created) VALUES (1, ?, ?, ?)",
                 (json.dumps(model_json), digest, created))
    row = conn.execute("SELECT id, model, digest, created FROM field_models WHERE id = 1").fetchone()
    conn.execute("UPDATE field_models SET row_digest = ? WHERE id = 1",
                 (value_digest([("field_models",), tuple(row)]),))


def read_field_model(conn: sqlite3.Connection) -> tuple[dict, str] | None:
    """The stored field model's JSON and digest, or None (also when it fails its row digest: fitted again)."""
    r = conn.execute("SELECT id, model, digest, created, row_digest FROM field_models WHERE id = 1").fetchone()
    if r is None or r[4] != value_digest([("field_models",), tuple(r)[:4]]):
        return None
    return json.loads(r[1]), r[2]

"""Camera displacement series in a campaign: import, storage and cross-validation with LiDAR."""
from __future__ import annotations

import datetime as dt
import json
import os
from pathlib import Path

import numpy as np

from common.errors import ProcessingError
from common.files import csv_text, json_safe, output_folder, write_atomic
from common.series import Series, series_arrays_from_npz, series_npz_bytes
from lidar.figures import save_figure
from projects.store.campaign import CAMERA_DIR, Campaign, parse_datetime
from projects.store.errors import InputError
from projects.store.history import histories, ns_of
from projects.store.records import SeriesRecord
from vision.crossval import CrossValidation, cross_validate
from vision.figures import difference_figure, overlay_figure, scatter_figure
from vision.series import read_camera_series


def midspan_reflector(c: Campaign) -> str:
    """The measurement target nearest the middle between the piers (mean of the reference targets)."""
    refl = [r for r in c.reflectors() if not r.retired]
    refs = np.array([r.xyz_layout for r in refl if r.is_reference], float)
    meas = [r for r in refl if not r.is_reference]
    if not meas:
        raise InputError("the campaign has no measurement target to pair the camera with")
    if len(refs) == 0:
        return meas[0].id
    mid = refs.mean(axis=0)
    return min(meas, key=lambda r: float(np.linalg.norm(np.array(r.xyz_layout) - mid))).id


def import_series(c: Campaign, path: str | os.PathLike, *, name: str | None = None,
                  reflector: str | None = None, column: str | None = None, timezone: str | None = None,
                  unit: str | None = None, positive: str = "up") -> tuple[str, Series]:
    """Read a camera series file, copy it into the campaign (read-only) and store the series.

    ``timezone`` is the zone of times without an offset (default: the campaign's, :attr:`Campaign.timezone`);
    the series' ``times_read`` says which was assumed. Nothing changes in the campaign unless the whole file was
    read; a file already imported (same checksum) or an existing name is refused.
    """
    path, name = c.series.check_new("camera_series", path, name, "a camera series")
    rid = reflector or midspan_reflector(c)
    if c.reflector(rid).is_reference:
        raise InputError(f"{rid} is a reference target; pair the camera with a measurement target")
    sha = c.series.checksum_if_new("camera_series", path)
    timezone = timezone or c.timezone
    series = read_camera_series(path, column=column, timezone=timezone, unit=unit, positive=positive)
    options = {"column": series.column, "unit": series.unit_read, "timezone": timezone, "positive": positive}
    summary = {**series.summary(), "unit": series.unit_read}  # the stored record's 'unit': the file's (format 1)

    def record(conn, rel):
        c.series.insert(conn, "camera_series", name=name, reflector=rid, sha256=sha, stored_path=rel,
                        original_path=str(path.resolve()), options=options, summary=summary,
                        arrays=series_npz_bytes(series.time_ns, series.values))
        c.log_action(conn, "camera-import", None, {"name": name, "file": str(path), "sha256": sha, "rows": len(series),
                                              "bad_rows": series.n_bad, "reflector": rid})

    c.import_file(path, sha, CAMERA_DIR, record, journal_entry={  # what 'repair' needs to read it again
        "kind": "camera", "name": name, "reflector": rid,
        "read": {"column": column, "timezone": timezone, "unit": unit, "positive": positive}})
    return name, series


def series_records(c: Campaign) -> list[SeriesRecord]:
    """The imported camera series (without their arrays)."""
    return c.series.records("camera_series")


def load_series(c: Campaign, name: str | None = None) -> tuple[SeriesRecord, Series]:
    """One stored series (the only one when ``name`` is None)."""
    rows = series_records(c)
    if not rows:
        raise InputError(f"{c.folder}: no camera series yet; import one with 'bridgesurvey camera import'")
    if name is None:
        if len(rows) > 1:
            raise InputError(f"the campaign has {len(rows)} camera series ({', '.join(r.name for r in rows)}); "
                             "choose one with --series")
        row = rows[0]
    else:
        match = [r for r in rows if r.name == name]
        if not match:
            raise InputError(f"no camera series {name!r}; the campaign has {', '.join(r.name for r in rows)}")
        row = match[0]
    t, v = series_arrays_from_npz(c.series.arrays("camera_series", row.name))
    s = row.summary
    return row, Series(time_ns=t, values=v, unit="mm", unit_read=row.options["unit"], source=row.original_path,
                       column=row.options["column"], n_bad=s["bad_rows"], n_missing=s["missing_values"],
                       sampling_s=s["sampling_s"] or float("nan"))


def crossvalidate(c: Campaign, *, series: str | None = None, reflector: str | None = None,
                  align_at: str | None = None, window_min: float = 30.0) -> tuple[CrossValidation, Series]:
    """Cross-validate a stored camera series with the LiDAR displacements of its reflector."""
    row, cam = load_series(c, series)
    rid = reflector or row.reflector or midspan_reflector(c)
    c.reflector(rid)
    if not (np.isfinite(window_min) and window_min > 0):
        raise InputError(f"--window-min must be a positive number of minutes, got {window_min}")
    h = histories(c, targets=[rid]).get(rid)
    if h is None:
        raise ProcessingError(f"no LiDAR displacements of {rid} yet; run 'bridgesurvey process' first")
    at = ns_of(dt.datetime.fromisoformat(parse_datetime(align_at))) if align_at else None
    return cross_validate(list(h.epochs), h.time_ns, h.displacement_mm, h.sigma_mm, cam, window_s=window_min * 60.0,
                          align_at_ns=at, reflector=rid, series=row.name), cam


def save_crossval(c: Campaign, cv: CrossValidation) -> None:
    """Keep the cross-validation summary in the campaign (the report shows it)."""
    c.crossvals.save(cv.series, json_safe(cv.to_json()),
                            {"series": cv.series, "reflector": cv.reflector, "n_pairs": cv.n_pairs,
                             "bias_mm": cv.bias_mm, "rmse_mm": cv.rmse_mm})


def crossval_summaries(c: Campaign) -> list[dict]:
    """Every stored cross-validation summary (JSON documents of :class:`vision.crossval.CrossValidation`)."""
    return [r.summary for r in c.crossvals.all()]


def write_crossval_outputs(cv: CrossValidation, camera: Series, out_dir: str | os.PathLike) -> list[Path]:
    """``crossval.json``, ``crossval.csv`` and the overlay, difference and scatter plots (PNG)."""
    out = output_folder(out_dir)
    table = json_safe(cv.to_json())  # NaN -> None, which to_csv writes as an empty cell
    paths = [write_atomic(out / "crossval.json", json.dumps(table, indent=2) + "\n")]
    rows = [{**p, "flags": ";".join(p["flags"])} for p in table["pairs"]]
    cols = ["epoch", "datetime", "lidar_mm", "lidar_sigma_mm", "camera_mm", "camera_raw_mm", "camera_sigma_mm",
            "camera_n", "difference_mm", "sigma_mm", "flags"]
    paths.append(write_atomic(out / "crossval.csv", csv_text(rows, cols)))
    for name, fig in (("overlay.png", overlay_figure(cv, camera)), ("difference.png", difference_figure(cv)),
                      ("scatter.png", scatter_figure(cv))):
        paths.append(save_figure(fig, out / name))
    return paths

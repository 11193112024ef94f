"""Is the campaign whole: verify it end to end, and repair what a restore or damage left (both front ends).

:func:`verify_campaign` is the store's check (:func:`projects.store.verify.verify_store`: the database,
every imported file, the files it does not list, every stored result's checksum) plus processing's view
(results that no longer match their inputs). :func:`repair_folder` sets a damaged schema version from the
tables and registers again every file a restored older database lost, reading series again with the
options of their import. Neither deletes anything.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from common.progress import ProgressCallback
from projects.processing.stages import baseline_epoch, stale_epochs
from projects.series.camera import import_series
from projects.series.environment import import_env
from projects.series.predictions import import_prediction
from projects.store.campaign import Campaign
from projects.store.repair import repair_campaign, repair_schema_version
from projects.store.verify import Finding, verify_store


def _stale(c: Campaign) -> list[Finding]:
    """Results that do not match their inputs (processing's view), as findings."""
    out = [Finding("stale", f"epoch {label}", f"results are stale ({why})", "run 'bridgesurvey process'")
           for label, why in stale_epochs(c).items()]
    base = baseline_epoch(c)
    for e in c.epochs():
        res, ds = c.result(e.label), c.displacement_set(e.label)
        if res is not None and res.stage == "measured" and base is not None and (ds is None or ds.baseline != base):
            out.append(Finding("stale", f"epoch {e.label}", "displacements missing or against another baseline",
                               "run 'bridgesurvey process'"))
    return out


def verify_campaign(c: Campaign, *, progress: ProgressCallback | None = None) -> list[Finding]:
    """Every problem the campaign has, each with what to do (empty when it is whole)."""
    found = verify_store(c, progress=progress)
    if any(table != "field_models" for table, _ in c.damaged_inputs()):
        return found  # damaged inputs (named): whether results match them cannot be said until they are put right
    return found + _stale(c)


def reimporters() -> dict[str, Callable]:
    """How each kind of series file is read again (with the options of its import, from the journal)."""
    def camera(c, path, e):
        name, _ = import_series(c, path, name=e.get("name"), reflector=e.get("reflector"), **e.get("read", {}))
        return f"{path.parent.name}/{path.name}: camera series {name!r} read again"

    def environment(c, path, e):
        name, _ = import_env(c, path, kind=e["series_kind"], name=e.get("name"), **e.get("read", {}))
        return f"{path.parent.name}/{path.name}: environment series {name!r} read again"

    def prediction(c, path, e):
        targets = import_prediction(c, path, **e.get("read", {}))
        return f"{path.parent.name}/{path.name}: design prediction of {', '.join(sorted(targets))} read again"

    return {"camera": camera, "environment": environment, "prediction": prediction}


def repair_folder(folder: str | os.PathLike) -> tuple[list[str], list[str]]:
    """Repair a campaign folder; (what was done, what was left as it is). Nothing is deleted."""
    schema_notes = repair_schema_version(Path(folder))
    with Campaign.open(folder) as c:
        rep = repair_campaign(c, reimporters())
    return schema_notes + list(rep.done), list(rep.left)

"""What goes into a survey report, gathered from a campaign (no PDF code here).

:func:`gather` reads everything the report shows for a scope (one epoch, a
period or the whole campaign) into plain frozen dataclasses, so the PDF
builder and any other front end (the desktop application) draw the same facts.
"""
from __future__ import annotations

import datetime as dt
import getpass
import logging
import platform
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

import numpy as np

from common.errors import InputError, SurveyError
from common.flags import FLAG_SECOND_OBJECT
from common.progress import ProgressCallback, report
from lidar.systematic.corrections import cos_incidence_of
from projects.analysis.run import analyse_campaign
from projects.compare.whole_scan import comparisons
from projects.processing.stages import PIPELINE_VERSION, baseline_epoch, parameters
from projects.results.state import epoch_states
from projects.results.table import damaged_line, displacement_table
from projects.series.camera import crossval_summaries, load_series
from projects.series.context import plot_context
from projects.store import schema
from projects.store.campaign import Campaign
from projects.store.history import DisplacementHistory, histories
from projects.store.inputs import COMPUTABLE_YEARS
from projects.store.previews import MapPreview
from projects.store.records import (
    DisplacementSet,
    Epoch,
    LimitRecord,
    LogEntry,
    ReferenceCheck,
    Reflector,
    ScanFile,
    StoredPlan,
)

log = logging.getLogger(__name__)

PACKAGES = ("bridgesurvey", "numpy", "scipy", "laspy", "lazrs", "pye57", "open3d", "py4dgeo", "matplotlib",
            "reportlab", "svglib")


@dataclass(frozen=True)
class ReportScope:
    """Which epochs a report covers: one epoch, a period, or (both None) everything."""

    epoch: str | None = None
    start: str | None = None
    end: str | None = None


@dataclass(frozen=True)
class TargetState:
    """One reflector's situation at the last epoch of the report."""

    reflector: str
    group: str
    installed: str | None
    retired: str | None
    replaces: str | None
    found: bool | None
    flags: tuple[str, ...]
    remarks: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class EpochSection:
    """Everything the report shows about one epoch."""

    label: str
    datetime: str
    notes: str
    stage: str  # the stored result's stage (imported, planned, measured)
    plan: StoredPlan | None
    preview: MapPreview | None
    centroids: dict
    reference_checks: tuple[ReferenceCheck, ...]
    displacement_set: DisplacementSet | None
    files: tuple[ScanFile, ...]
    state: str = "imported"  # as ``status`` gives it (projects.results.state.epoch_states)
    state_flags: tuple[str, ...] = ()
    systematics: dict = field(default_factory=dict)  # what its displacements were corrected for (scale, drift)
    setups: dict = field(default_factory=dict)  # how its set-ups were joined (lidar.setups), if several
    damaged: str = ""  # the line saying its stored displacements are damaged and left out (empty: they are not)
    setup_plans: dict = field(default_factory=dict)  # set-up k > 1 -> (its StoredPlan or None, its centroids)


@dataclass(frozen=True, eq=False)
class ReportContent:
    """The facts of one report."""

    name: str
    folder: str
    span_m: float | None
    scanner: str
    author: str
    generated: str
    scope: ReportScope
    scope_text: str
    baseline: str | None
    epochs: tuple[EpochSection, ...]
    displacements: tuple[dict, ...]      # rows of projects.exports.displacement_table within the scope
    histories: dict[str, DisplacementHistory]  # per target, within the scope
    reflectors: tuple[Reflector, ...]
    target_states: tuple[TargetState, ...]
    limits: tuple[LimitRecord, ...]
    parameters: dict
    versions: dict
    log: tuple[LogEntry, ...]
    extras: dict[str, Any]               # optional sections (comparisons, camera cross-validation) by name

    @property
    def period(self) -> tuple[str, str]:
        return (self.epochs[0].datetime, self.epochs[-1].datetime) if self.epochs else ("", "")


def select_epochs(c: Campaign, scope: ReportScope) -> list[Epoch]:
    """The campaign's epochs (in time order) that a scope covers; InputError for unknown labels."""
    epochs = c.epochs()
    if not epochs:
        raise InputError(f"{c.folder}: the campaign has no epochs yet; add one (Epoch ▸ Add epoch… in the "
                         "application, or 'bridgesurvey add-epoch DIR')")
    for e in epochs:  # every date goes on a time axis (history plots): one the axis cannot hold is one line
        if not COMPUTABLE_YEARS[0] <= e.when.year <= COMPUTABLE_YEARS[1]:
            raise InputError(f"{c.folder}: epoch {e.label} is dated {e.datetime[:10]}, outside the years a report can "
                             f"place on a time axis ({COMPUTABLE_YEARS[0]} to {COMPUTABLE_YEARS[1]}); no report was "
                             "written: restore campaign.sqlite from a backup made before that epoch was added")
    labels = [e.label for e in epochs]
    for lab in (scope.epoch, scope.start, scope.end):
        if lab is not None and lab not in labels:
            raise InputError(f"unknown epoch {lab!r}; the campaign has {labels[0]} ... {labels[-1]} "
                             "(see the campaign tree, or 'bridgesurvey status DIR')")
    if scope.epoch is not None:
        if scope.start or scope.end:
            raise InputError("give either --epoch or --from/--to, not both")
        return [epochs[labels.index(scope.epoch)]]
    i0 = labels.index(scope.start) if scope.start else 0
    i1 = labels.index(scope.end) if scope.end else len(labels) - 1
    if i1 < i0:
        raise InputError(f"--from {scope.start} comes after --to {scope.end}")
    return epochs[i0:i1 + 1]


def versions() -> dict:
    """Versions of Python, the pipeline, the campaign schema and the libraries that shaped the numbers."""
    out = {"python": platform.python_version(), "pipeline": PIPELINE_VERSION,
           "campaign schema": str(schema.SCHEMA_VERSION)}
    for p in PACKAGES:
        try:
            out[p] = metadata.version(p)
        except metadata.PackageNotFoundError:
            pass
    return out


def _target_states(c: Campaign, last: EpochSection | None) -> list[TargetState]:
    moved = {r.reflector for r in (last.reference_checks if last else ()) if r.moved or r.suspect}
    reflectors = c.reflectors()
    replaced_by = {r.replaces: r.id for r in reflectors if r.replaces}
    out = []
    for r in reflectors:
        t = last.centroids.get(r.id) if last else None
        flags = tuple(t.flags) if t is not None else ()
        remarks = []
        if t is not None and not t.found:
            remarks.append("not found (occluded or removed)")
        if FLAG_SECOND_OBJECT in flags:
            remarks.append("contamination beside the target left out")
        if r.id in moved:
            remarks.append("moved reference: left out of the reference group")
        if r.replaces:
            remarks.append(f"replaces {r.replaces}")
        if r.id in replaced_by:
            remarks.append(f"replaced by {replaced_by[r.id]}")
        if r.retired and last is not None and r.retired <= last.datetime:
            remarks.append(f"retired {r.retired[:10]}")
        out.append(TargetState(r.id, r.group, r.installed, r.retired, r.replaces,
                               None if t is None else bool(t.found), flags, tuple(remarks)))
    return out


def _field_extra(c: Campaign, sections: Sequence[EpochSection]) -> dict | None:
    """What the field error budget page shows: the model, each epoch's record, times, the centroids' geometry."""
    stored = c.field_model()
    if stored is None or not any(s.systematics for s in sections):
        return None
    measured = [(float(np.linalg.norm(t.xyz_socs)), cos_incidence_of(t))
                for s in sections for t in s.centroids.values() if t.found]
    return {"model": stored[0], "systematics": {s.label: s.systematics for s in sections},
            "times": {s.label: s.datetime for s in sections}, "measured": measured}


def gather(c: Campaign, scope: ReportScope = ReportScope(), *, author: str | None = None,
           with_previews: bool = True, progress: ProgressCallback | None = None) -> ReportContent:
    """Collect the report's facts for ``scope`` from an open campaign (``progress``: per epoch, then per part)."""
    chosen = select_epochs(c, scope)
    sections = []
    states = epoch_states(c, [e.label for e in chosen])  # once: each reads every displacement of the campaign
    for k, e in enumerate(chosen):
        lab = e.label
        report(progress, 0.6 * k / len(chosen), f"reading epoch {lab}")
        res = c.result(lab)
        state, state_flags = states[lab].state, states[lab].flags
        sections.append(EpochSection(
            lab, e.datetime, e.notes, res.stage if res else "imported",
            c.stored_plan(lab), c.map_preview(lab) if with_previews else None,
            c.centroids(lab), tuple(c.reference_checks(lab)), c.displacement_set(lab), tuple(c.files(lab, setup=None)),
            state, tuple(state_flags), c.systematics(lab), c.systematics(lab).get("setups") or {},
            damaged_line(c, [lab]) or "",
            {k: (c.stored_plan(lab, k), c.centroids(lab, k)) for k in c.setups(lab) if k != 1}))
    last_time = chosen[-1].datetime
    first_time = chosen[0].datetime
    # A visit report shows the history up to the visit; a period report the period itself.
    since = "" if scope.epoch is not None else first_time
    report(progress, 0.6, "reading the displacements")
    rows = [r for r in displacement_table(c) if since <= r["datetime"] <= last_time]
    if scope.epoch is not None:  # a visit report shows the history up to that visit
        text = f"visit of {chosen[0].datetime[:16].replace('T', ' ')} (epoch {scope.epoch})"
    elif len(chosen) == len(c.epochs()):
        text = f"whole campaign, {len(chosen)} epochs"
    else:
        text = f"period {chosen[0].label} to {chosen[-1].label}, {len(chosen)} epochs"
    in_scope = {r["epoch"] for r in rows}
    report(progress, 0.7, "reading the histories and comparisons")
    hist = {rid: h.select([lab in in_scope for lab in h.epochs]) for rid, h in histories(c).items()}

    extras: dict[str, Any] = {}
    cmp_ = comparisons(c, {s.label for s in sections} | ({baseline_epoch(c)} if scope.epoch else set()))
    if cmp_:
        extras["comparisons"] = cmp_

    cvs = crossval_summaries(c)
    if cvs:
        extras["crossvals"] = [(s, load_series(c, s["series"])[1]) for s in cvs]

    extras["context"] = plot_context(c)
    if len({r["epoch"] for r in rows}) >= 4:
        report(progress, 0.8, "analysing temperature, events and trend")
        try:
            extras["analysis"] = analyse_campaign(c)
        except SurveyError as exc:  # no displacements to analyse: the report says so elsewhere
            log.info("no analysis section: %s", exc)
    field_extra = _field_extra(c, sections)
    if field_extra is not None:
        extras["field"] = field_extra
    report(progress, 1.0, "the campaign read")
    log_rows = [r for r in c.log() if r.epoch is None or r.epoch in {s.label for s in sections}]
    return ReportContent(
        name=c.name, folder=str(c.folder), span_m=c.span_m, scanner=c.profile.name,
        author=author or getpass.getuser(),
        generated=dt.datetime.now(dt.UTC).astimezone().isoformat(timespec="seconds"),
        scope=scope, scope_text=text, baseline=baseline_epoch(c), epochs=tuple(sections), displacements=tuple(rows),
        histories=hist, reflectors=tuple(c.reflectors()), target_states=tuple(_target_states(c, sections[-1])),
        limits=tuple(c.limits()), parameters=parameters(c), versions=versions(), log=tuple(log_rows), extras=extras)

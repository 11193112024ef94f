"""Processing a campaign: plan, measure and compute displacements, incrementally.

Stage 1 (per epoch): coarse scan -> plan; fine scans -> centroids. Its inputs
hash covers the scan checksums, the reflectors expected at that date, the
parameters and the pipeline version; an epoch whose hash is unchanged is not
recomputed. Stage 2 (:mod:`lidar.stage2`, a pure job on one snapshot of the
campaign, :func:`stage2_inputs`): the field model and the displacements against
the baseline, hashed on the stage-1 hashes of the epoch and of its baseline(s),
the displacement parameters and the field model's terms. Adding epoch 100
therefore computes epoch 100 only; changing a parameter marks exactly the
epochs it affects as stale. This module decides what is stale, reads the
store and writes what the jobs computed; it computes no number itself.
"""
from __future__ import annotations

import functools
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from common.errors import CancelledError, InputError, ProcessingError, SurveyError
from common.flags import PROBLEM, severity
from common.progress import ProgressCallback, report, scaled
from common.series import series_arrays_from_npz
from lidar.io import read_scan
from lidar.io.poses import read_in_scanner_frame
from lidar.layout import Layout
from lidar.plan import PlanTarget, ScanPlan
from lidar.scan import Scan
from lidar.scanner_profile import MAX_TILT_DEG, ScannerProfile
from lidar.stage2 import (
    Stage2Inputs,
    StoredDisplacement,
    VisitInputs,
    inputs_digest,
    revisions,
    run_stage2,
    stale_parts,
)
from lidar.systematic.campaign_fit import air_near
from lidar.visit_plan import SetupTargets, VisitPlan, plan_visit
from projects.processing.parameters import DEFAULTS, parameter, stage1_params, stage2_params, visit_budget_seconds
from projects.store.archive import check_present
from projects.store.campaign import Campaign, parse_datetime, sha256_of
from projects.store.errors import ScansArchivedError
from projects.store.records import EpochInputs, ScanFile

log = logging.getLogger(__name__)

#: Why an epoch whose plan and results are sound is planned again.
PREVIEW_DAMAGED = "its map preview is damaged (fails its checksum): planned again to remake it"
#: Why a stored visit was recomputed when only the campaign's field model changed (a newer visit re-fitted it).
FIELD_REFIT = "the field model was re-fitted with the newer visits"

PIPELINE_VERSION = "1"
#: Version of the centroid estimate, in every stage-1 result's inputs: a change re-measures stored epochs from
#: their kept plans (2: the disc's normal fitted on the ranges alone, see lidar.centroid._plane; 3: weak discs,
#: 20-35 % of the beam's width, measured with a widened sigma instead of refused, see lidar.centroid.WEAK_RATIO;
#: 4: the disc's outline overrules a predicted grazing view, and a surface that moved during the window is
#: corrected from the points' times, see lidar.centroid.apparent_cos and lidar.transients; 5: stray bright returns
#: beside a grazing disc are no second object below lidar.centroid.SECOND_OBJECT_SHARE_GRAZING; 6: the disc's
#: centre in its plane weighted by every return's intensity, see lidar.centroid.weighted_centre; 7: the weighted
#: centre kept where it is far from the thresholded one, with a sigma covering both, see
#: lidar.centroid.WEIGHTED_AGREEMENT).
CENTROID_VERSION = "7"
#: Profile fields added later: they enter the input hash only when they differ from their default.
_LATER_PROFILE_FIELDS = {"max_tilt_deg": MAX_TILT_DEG, "kind": "line", "step_presets": [], "windowed": True,
                         "horizontal_direction": "ccw", "horizontal_zero_deg": 0.0, "vertical_reference": "zenith",
                         "resolution_label": "step", "quality": "", "wavelength_nm": 1550.0,
                         "drift_tolerance_arcsec": 10.0}


@functools.lru_cache(maxsize=64)
def _profile_key(profile: ScannerProfile) -> dict:
    """The profile as it enters the input hash (one dict shared by every caller: read it, never change it).

    What decides the plan and the centroids (a field added
    later only when it differs from its default; sources and notes never). Remembered by profile (a frozen
    value): the staleness check of ``status`` needs it once a set-up of every visit.
    """
    d = profile.to_dict()
    for k, default in _LATER_PROFILE_FIELDS.items():
        if d.get(k) == default:
            del d[k]
    for k in ("sources", "notes"):
        d.pop(k, None)
    return d


def _pipeline():
    """:mod:`lidar.pipeline`, imported when stage 1 first computes."""
    # local: its scikit-image and SciPy: 0.3-0.6 s of the start-up of status and every read-only command (measured)
    from lidar import pipeline

    return pipeline


def max_tilt(c: Campaign, params: dict, label: str | None = None) -> float | None:
    """Largest tilt an identification may imply: None when the scanner was not levelled."""
    return _tilt_limit(params, c.profile_for(label))


def layout_up(params: dict) -> np.ndarray:
    """The layout's up direction from the ``layout_up`` setting, shape (3,)."""
    return np.array([float(v) for v in str(params["layout_up"]).split(",")])


def set_parameter(c: Campaign, key: str, text: str | None) -> None:
    """Change one processing parameter (or the baseline, or the casting date) from its text form, validated."""
    p = parameter(key)
    if p.stage == "baseline":
        value = p.parse(text or "")
        if value:
            c.epoch(value)
        c.set_setting("baseline", value)
        return
    if p.stage == "analysis":  # concrete age axes and predictions by age

        c.set_setting(key, parse_datetime(text) if text else None)
        return
    c.set_setting(key, p.value_of(text))


def parameters(c: Campaign) -> dict:
    """The campaign's processing parameters: the defaults overridden by its settings."""
    return _parameters_of(c.settings())


def _parameters_of(settings: dict) -> dict:
    return {**DEFAULTS, **{k: v for k, v in settings.items() if k in DEFAULTS}}


_hash = inputs_digest


@dataclass
class EpochOutcome:
    """What processing did to one epoch: planned, measured, up-to-date or failed, with a message."""

    epoch: str
    action: str  # planned, measured, up-to-date, failed
    message: str = ""
    archived: bool = False  # failed only because scans it needs were archived out of the campaign folder


@dataclass
class ProcessSummary:
    """What a processing run did: each epoch's outcome, the epochs with new displacements and their problems."""

    outcomes: list[EpochOutcome] = field(default_factory=list)
    displacement_epochs: list[str] = field(default_factory=list)
    displacement_reasons: dict[str, str] = field(default_factory=dict)  # epoch -> why it was recomputed
    baseline: str | None = None
    problems: dict[str, str] = field(default_factory=dict)  # epoch -> its first problem flag

    @property
    def failed(self) -> list[EpochOutcome]:
        return [o for o in self.outcomes if o.action == "failed"]


def check_scan(path: str | Path, sha256: str | None) -> None:
    """Raise the one line when a stored scan no longer has the checksum recorded at its import.

    A file changed in the campaign folder (a flipped byte in a header scales every coordinate) would
    otherwise give displacements off by a millimetre without a flag. The cost: SHA-256 over the file,
    0.35 s of CPU for a 100 MB scan on our machine (``sha256sum``'s user time; 0.5 s wall under load),
    against several seconds to decode the same file's points; the reader then finds it in the page cache.
    """
    if not sha256:
        return
    folder = Path(path).parent.parent
    try:
        got = sha256_of(Path(path))
    except OSError as exc:
        raise ProcessingError(f"{path}: the scan cannot be read ({exc.strerror}); 'bridgesurvey verify {folder}' "
                              "says what to do") from None
    if got != sha256:
        raise ProcessingError(f"{path}: this scan changed since its import (its checksum is not the one recorded "
                              "then), so its visit is not processed with it; restore it from a backup or import the "
                              f"original again ('bridgesurvey verify {folder}' lists every changed file)")


def read_paths(paths, progress: ProgressCallback | None = None, frames: Sequence = (),
               sha256s: Sequence[str] = ()) -> Scan:
    """Scan files as one scan (each file's share of the progress in turn).

    ``frames`` gives each file's :class:`lidar.io.poses.FileFrame` (which of its scans, the pose carrying
    points exported in a project frame into the scanner's); empty or None entries read a file as it is.
    ``sha256s`` are the files' checksums recorded at their import: each file is checked against its own
    before it is read (:func:`check_scan`); empty: not checked.
    """
    for p, sha in zip(paths, sha256s, strict=False):
        check_scan(p, sha)
    frames = tuple(frames) or (None,) * len(paths)
    scans = [read_in_scanner_frame(p, fr, progress=scaled(progress, k / len(paths), (k + 1) / len(paths)))
             if fr is not None else read_scan(p, progress=scaled(progress, k / len(paths), (k + 1) / len(paths)))
             for k, (p, fr) in enumerate(zip(paths, frames, strict=False))]
    return scans[0] if len(scans) == 1 else Scan.concatenate(scans)


def read_files(c: Campaign, files: Sequence[ScanFile], progress=None, *, setup: int = 1, what: str = "this") -> Scan:
    """The stored scan files ``files`` (from ``Campaign.files``) of one set-up as one scan, in its scanner frame.

    Scans archived out of the campaign folder stop it in one line naming them, where they are and the remedy
    (:func:`projects.store.archive.check_present`; ``what`` says what needs them).
    """
    check_present(c, files, what)
    return read_paths([c.path_of(f) for f in files], progress, [f.frame_for(setup) for f in files],
                      [f.sha256 for f in files])


def plan_inputs(c: Campaign, label: str, params: dict, setup: int = 1) -> tuple[str, object]:
    """(hash of the inputs, layout) of an epoch's (set-up's) plan.

    Its coarse scans, the layout at its date, the parameters, the scanner, and the other set-ups' coarse scans
    when the visit's set-ups are planned together.
    """
    inp = c.epoch_inputs(label, plan=False, setup=setup)
    return _plan_hashes(c, label, setup, inp, params)[2], inp.layout


@dataclass(frozen=True, eq=False)
class OtherSetup:
    """Another set-up of the visit, as a set-up planned together with it needs it (plain, picklable values).

    ``candidates`` are its plan's targets when its stored plan was made from its present coarse scans (then they
    are not analysed again); otherwise its coarse files are read and analysed by the job. ``frozen_plan`` is its
    stored plan JSON when its fine scans are imported and that plan was made from its present inputs
    (:func:`_frozen_hash`): it is taken as given, not planned again.
    """

    setup: int
    own_hash: str
    profile: ScannerProfile
    candidates: tuple[PlanTarget, ...] | None
    coarse_paths: tuple[str, ...] = ()
    coarse_frames: tuple = ()
    coarse_sha256: tuple[str, ...] = ()
    station_xy: tuple[float, float] | None = None
    frozen_plan: dict | None = None


def _frozen_hash(c: Campaign, label: str, inp: EpochInputs, own: str) -> str | None:
    """The stored plan hash of a set-up whose plan is frozen, else None.

    A set-up's plan is frozen once its fine scans are imported, when its stored plan was made from its present
    own inputs (its coarse scans, the layout, the parameters, the scanner; alone or together with the set-ups there
    were then): its windows are scanned, so a set-up added later must not plan them again. On site the second
    station's coarse scan comes after the first station's fine scans (issue 40).
    """
    if not inp.fine:
        return None
    sp = inp.plan if inp.plan is not None else c.stored_plan(label, inp.setup)
    if sp is None:
        return None
    if sp.inputs_hash == own or sp.plan_json.get("own_inputs") == own:
        return sp.inputs_hash
    return None


def _others(c: Campaign, label: str, setup: int, setups: Sequence[int], params: dict) -> tuple[OtherSetup, ...]:
    """The other set-ups (of ``setups``, the visit's) planned together with ``setup`` (none: one, or planned alone)."""
    if len(setups) < 2 or not params.get("plan_together", True):
        return ()
    out = []
    for k in setups:
        if k == setup:
            continue
        inp = c.epoch_inputs(label, setup=k)
        if not inp.coarse:
            continue
        own = _plan_hash(inp, params)
        doc = inp.plan.plan_json if inp.plan is not None else {}
        cands = _candidates_from_json(doc.get("candidates")) if doc.get("own_inputs") == own else None
        frozen = doc if _frozen_hash(c, label, inp, own) is not None else None
        out.append(OtherSetup(k, own, inp.profile, cands, tuple(str(c.path_of(r)) for r in inp.coarse),
                              tuple(r.frame_for(k) for r in inp.coarse), tuple(r.sha256 for r in inp.coarse),
                              _station_hint(k, params), frozen))
    return tuple(out)


def _visit_hash(own: str, others: Mapping[int, str], params: dict) -> str:
    """A set-up's plan hash: its own inputs', and with others planned together theirs and the visit's budget.

    ``others``: set-up -> own hash; the budget is :func:`projects.processing.parameters.visit_budget_seconds`'s.
    """
    if not others:
        return own
    return _hash({"own": own, "visit": [[k, others[k]] for k in sorted(others)],
                  "visit_budget_s": visit_budget_seconds(params, len(others) + 1)})


def _plan_hashes(c: Campaign, label: str, setup: int, inp: EpochInputs, params: dict
                 ) -> tuple[str, tuple[OtherSetup, ...], str]:
    """A set-up's own plan hash, the set-ups planned together with it, and its plan hash within the visit.

    A frozen set-up (:func:`_frozen_hash`) keeps its stored plan's hash: set-ups added after its fine scans do not
    make it stale, nor does turning ``plan_together`` on or off. The others' own hashes enter a set-up's hash whether they are frozen or not, so that a set-up
    planned together with another one is not planned again when that one's fine scans come in.
    """
    own = _plan_hash(inp, params)
    others = _others(c, label, setup, inp.setups, params)
    frozen = _frozen_hash(c, label, inp, own) if len(inp.setups) > 1 else None  # alone or together
    return own, others, frozen or _visit_hash(own, {o.setup: o.own_hash for o in others}, params)


def _candidates_to_json(targets: Sequence[PlanTarget]) -> list[dict]:
    return [{"id": t.id, "group": t.group, "xyz": [float(v) for v in t.xyz_socs], "diameter_m": t.diameter_m,
             "predicted": t.predicted, "incidence_cos": t.incidence_cos,
             "normal": None if t.normal_socs is None else [float(v) for v in t.normal_socs]} for t in targets]


def _candidates_from_json(rows) -> tuple[PlanTarget, ...] | None:
    """A stored plan's candidates (None when it has none or they are malformed: then they are analysed again)."""
    if not isinstance(rows, list):
        return None
    try:
        return tuple(PlanTarget(str(r["id"]), str(r["group"]), tuple(float(v) for v in r["xyz"]),
                                float(r["diameter_m"]), bool(r["predicted"]),
                                None if r["incidence_cos"] is None else float(r["incidence_cos"]),
                                None if r["normal"] is None else tuple(float(v) for v in r["normal"]))
                     for r in rows)
    except (KeyError, TypeError, ValueError):
        return None


def _file_key(f: ScanFile, setup: int):
    """A file as it enters an input hash: its checksum, with how it is read when that is not as it is."""
    frame = f.frame_for(setup)
    return f.sha256 if frame is None else {"sha256": f.sha256, "frame": frame.key}


def _plan_hash(inp: EpochInputs, params: dict) -> str:
    if not inp.coarse:
        where = f"set-up {inp.setup} of epoch {inp.label}" if inp.setup != 1 else f"epoch {inp.label}"
        raise ProcessingError(f"{where} has no coarse scan")
    key = {"v": PIPELINE_VERSION, "coarse": [_file_key(f, inp.setup) for f in inp.coarse],
           "layout": inp.layout.to_rows(), "params": stage1_params(params),
           "profile": _profile_key(inp.profile)}
    return _hash(key)


def _measure_hash(inp: EpochInputs, plan_hash: str, *, version: str = CENTROID_VERSION) -> str:
    key = {"plan": plan_hash, "fine": [_file_key(f, inp.setup) for f in inp.fine]}
    return _hash(key if version == "1" else {**key, "centroids": version})


def _tilt_limit(params: dict, profile) -> float | None:
    if not params["levelled"]:
        return None
    return float(params["max_tilt_deg"]) if params["max_tilt_deg"] is not None else profile.max_tilt_deg


def _analyse(coarse: Scan, layout, params: dict, profile, progress: ProgressCallback | None = None, *,
             station_xy: tuple[float, float] | None = None):
    return _pipeline().analyse_coarse(coarse, layout, step_deg=params["map_step_deg"],
                                      threshold=params["detection_threshold"],
                                      tolerance_m=params["identification_tolerance_m"],
                                      max_tilt_deg=_tilt_limit(params, profile), up_layout=layout_up(params),
                                      station_xy=station_xy, progress=progress)


def _station_hint(setup: int, params: dict) -> tuple[float, float] | None:
    """Where the surveyor says set-up 1 stood (``station_xy``, layout metres), or None.

    Only a tie between two identifications reads it (a symmetric bridge turned end for end). It is never
    guessed from an earlier visit: a scanner standing at the other end this week would be taken for its
    mirror image, and every target named wrong without a word.
    """
    if setup != 1 or not params.get("station_xy"):
        return None
    x, y = (float(v) for v in str(params["station_xy"]).split(","))
    return (x, y)


def analyse_epoch_coarse(c: Campaign, label: str, layout, params: dict, *, setup: int = 1,
                         progress: ProgressCallback | None = None):
    """Reflectance map, detections and identification of an epoch's (set-up's) coarse scan with the parameters."""
    coarse = read_files(c, c.files(label, "coarse", setup=setup), scaled(progress, 0.0, 0.5), setup=setup,
                        what="the reflectance map")
    return _analyse(coarse, layout, params, c.profile_for(label, setup), scaled(progress, 0.5, 1.0),
                    station_xy=_station_hint(setup, params))


@dataclass(frozen=True, eq=False)
class Stage1Job:
    """Everything stage 1 of one epoch needs, as plain picklable values (no campaign handle).

    A worker
    process or another machine can run it with :func:`run_stage1`; only the campaign's owner saves the
    result (:func:`save_stage1`).

    ``stored_plan`` is the epoch's plan JSON when its inputs are unchanged (it is reused, not
    recomputed); ``measure_hash`` is None when the epoch has no fine scans yet. ``setup`` is which
    set-up of the visit it is, ``coarse_frames`` and ``fine_frames`` how each file is read (see
    :func:`read_paths`).
    """

    folder: str
    label: str
    coarse_paths: tuple[str, ...]
    fine_paths: tuple[str, ...]
    layout: Layout
    params: dict
    profile: ScannerProfile
    plan_hash: str
    stored_plan: dict | None
    measure_hash: str | None
    setup: int = 1
    coarse_frames: tuple = ()
    fine_frames: tuple = ()
    station_xy: tuple[float, float] | None = None  # the hint for a symmetric layout (see _station_hint)
    coarse_sha256: tuple[str, ...] = ()  # each file's checksum at its import, checked before it is read
    fine_sha256: tuple[str, ...] = ()
    own_hash: str = ""  # the hash of this set-up's own plan inputs (``plan_hash`` adds the others' when planned together)
    others: tuple[OtherSetup, ...] = ()  # the visit's other set-ups when its set-ups are planned together


@dataclass(frozen=True, eq=False)
class Stage1Result:
    """What :func:`run_stage1` computed.

    A new plan (with its map preview) unless the stored one was reused, and the centroids when the epoch has fine scans.
    """

    job: Stage1Job
    plan: ScanPlan
    new_plan_json: dict | None
    preview: tuple[bytes, str] | None
    centroids: dict | None
    closures: dict | None = None
    time_source: str = "none"


def stage1_job(c: Campaign, label: str, setup: int = 1, *, fine: bool = True) -> Stage1Job:
    """An epoch's (set-up's) stage-1 job as plain values (its stored plan reused when its inputs are unchanged).

    The scans the job will read (the coarse ones unless the plan is reused, the fine ones unless ``fine`` is
    False) must be in the campaign folder: archived ones stop it in one line (:func:`check_present`).
    """
    inp = c.epoch_inputs(label, setup=setup)  # one read: epoch, files, plan, layout, scanner, settings
    if setup not in inp.setups:
        c.check_setup(label, setup)
    params = _parameters_of(inp.settings)
    own, others, h = _plan_hashes(c, label, setup, inp, params)
    sp = inp.plan
    stored = sp.plan_json if sp is not None and sp.inputs_hash == h and not inp.preview_to_remake else None
    check_present(c, (inp.coarse if stored is None else ()) + (inp.fine if fine else ()),
                  "processing it again (stage 1: planning and centroids from its scans)")
    return Stage1Job(str(c.folder), label, tuple(str(c.path_of(r)) for r in inp.coarse),
                     tuple(str(c.path_of(r)) for r in inp.fine), inp.layout, params, inp.profile, h, stored,
                     _measure_hash(inp, h) if inp.fine else None, setup,
                     tuple(r.frame_for(setup) for r in inp.coarse), tuple(r.frame_for(setup) for r in inp.fine),
                     _station_hint(setup, params), tuple(r.sha256 for r in inp.coarse),
                     tuple(r.sha256 for r in inp.fine), own, others)


def stage1_jobs(c: Campaign, label: str) -> list[Stage1Job]:
    """The stage-1 jobs of every set-up of an epoch whose stored results no longer match their inputs."""
    return [stage1_job(c, label, k) for k in _stale_setups(c, label, parameters(c))]


def run_stage1(job: Stage1Job, *, progress: ProgressCallback | None = None) -> Stage1Result:
    """Plan (unless reused) and centroids of one epoch: pure computation on its files."""
    pipeline = _pipeline()
    # local: the preview's lidar.detection (scikit-image), as _pipeline's
    from projects.store.previews import encode_preview

    new_plan, preview = None, None
    if job.stored_plan is not None:
        plan = ScanPlan.from_json(job.stored_plan)
    else:
        coarse = read_paths(job.coarse_paths, scaled(progress, 0.0, 0.25), job.coarse_frames, job.coarse_sha256)
        analysis = _analyse(coarse, job.layout, job.params, job.profile, scaled(progress, 0.25, 0.4),
                            station_xy=job.station_xy)
        del coarse
        if job.others:
            plan, visit_doc = _plan_together(job, analysis, progress)
        else:
            plan = pipeline.plan_from_coarse(analysis, job.layout, epoch=job.label, profile=job.profile,
                                             min_points=int(job.params["min_points"]),
                                             budget_seconds=float(job.params["budget_min"]) * 60.0,
                                             up_layout=layout_up(job.params), closure=bool(job.params["closure"]),
                                             reference_factor=float(job.params["reference_points_factor"]))
            visit_doc = {}
        new_plan = {**plan.to_json(), **visit_doc}
        if job.setup != 1:
            new_plan["setup"] = job.setup
        new_plan["identification"] = {"missing": list(analysis.identification.missing),
                                      "missing_why": dict(analysis.missing_why),
                                      "extra_detections": len(analysis.identification.extra_detections),
                                      "fit_rms_m": analysis.identification.rms_m,
                                      "detections": len(analysis.detections.detections)}
        preview = encode_preview(analysis)
    measured = None
    if job.fine_paths:
        fine = read_paths(job.fine_paths, scaled(progress, 0.4, 0.8), job.fine_frames, job.fine_sha256)
        measured = pipeline.measure_fine(fine, plan, job.layout, profile=plan.profile)
    report(progress, 1.0, "measured" if measured is not None else "planned")
    if measured is None:
        return Stage1Result(job, plan, new_plan, preview, None)
    return Stage1Result(job, plan, new_plan, preview, dict(measured.centroids), dict(measured.closures),
                        measured.time_source)


def _plan_together(job: Stage1Job, analysis, progress: ProgressCallback | None) -> tuple[ScanPlan, dict]:
    """A set-up's plan within its visit's, planned together (:func:`lidar.visit_plan.plan_visit`).

    The other set-ups' targets come from their stored plans when those were made from their present coarse
    scans, else from their coarse scans, analysed here. A set-up whose fine scans are imported keeps the plan they
    were made with (``frozen_plan``); only the set-ups still to come are planned. Returns the plan and what its
    JSON adds: this set-up's candidates (so that the others need not analyse its coarse scan again) and the
    visit's summary.
    """
    pipeline = _pipeline()
    up = layout_up(job.params)
    mine = tuple(pipeline.plan_targets(analysis, job.layout, up_layout=up))
    setups = [SetupTargets(job.setup, mine, job.profile)]
    left_out = []
    for n, o in enumerate(job.others):
        cands = o.candidates
        frozen = ScanPlan.from_json(o.frozen_plan) if o.frozen_plan is not None else None
        if cands is None:
            sub = scaled(progress, 0.25 + 0.15 * n / len(job.others), 0.25 + 0.15 * (n + 1) / len(job.others))
            try:
                coarse = read_paths(o.coarse_paths, sub, o.coarse_frames, o.coarse_sha256)
                other = _analyse(coarse, job.layout, job.params, o.profile, station_xy=o.station_xy)
            except SurveyError as exc:  # its own plan says why; this one is made without it
                left_out.append(f"set-up {o.setup} is left out of this set-up's plan: its coarse scan cannot be "
                                f"planned ({str(exc).splitlines()[0]})")
                continue
            cands = tuple(pipeline.plan_targets(other, job.layout, up_layout=up))
        setups.append(SetupTargets(o.setup, cands, o.profile, frozen,
                                   frozen_alone=o.frozen_plan is not None and "visit" not in o.frozen_plan))
    visit: VisitPlan = plan_visit(setups, epoch=job.label, min_points=int(job.params["min_points"]),
                                  budget_seconds=visit_budget_seconds(job.params, len(job.others) + 1),
                                  closure=bool(job.params["closure"]),
                                  reference_factor=float(job.params["reference_points_factor"]))
    plan = visit.plan(job.setup)
    notes = pipeline.coarse_notes(analysis, mine, plan) + visit.warnings + tuple(left_out)
    if notes:
        plan = replace(plan, warnings=plan.warnings + notes)
    return plan, {"candidates": _candidates_to_json(mine), "own_inputs": job.own_hash,
                  "visit": visit.summary(job.setup)}


def save_stage1(c: Campaign, result: Stage1Result) -> None:
    """Store what :func:`run_stage1` computed (the campaign's single writer does this)."""
    job = result.job
    if result.new_plan_json is not None:
        c.save_plan(job.label, result.new_plan_json, job.plan_hash, preview=result.preview, setup=job.setup)
    if result.centroids is not None and job.measure_hash is not None:
        c.save_centroids(job.label, result.centroids, job.measure_hash, stage1_params(job.params),
                         closures=result.closures, time_source=result.time_source, setup=job.setup)


def plan_epoch(c: Campaign, label: str, *, setup: int = 1, progress: ProgressCallback | None = None) -> ScanPlan:
    """The fine-scan plan of an epoch's set-up, from its coarse scan (reused when its inputs are unchanged)."""
    job = stage1_job(c, label, setup, fine=False)
    if job.stored_plan is not None:
        return ScanPlan.from_json(job.stored_plan)
    result = run_stage1(replace(job, fine_paths=(), measure_hash=None), progress=progress)
    save_stage1(c, result)
    return result.plan


def plan_visit_epoch(c: Campaign, label: str, *, progress: ProgressCallback | None = None
                     ) -> tuple[dict[int, ScanPlan], dict[int, dict]]:
    """Every set-up's plan of a visit (planned when needed) and each one's summary of the visit (empty when alone)."""
    setups = [k for k in c.setups(label) if c.files(label, "coarse", setup=k)]
    plans, summaries = {}, {}
    for n, k in enumerate(setups):
        plans[k] = plan_epoch(c, label, setup=k, progress=scaled(progress, n / len(setups), (n + 1) / len(setups)))
        stored = c.stored_plan(label, k)
        summaries[k] = dict(stored.plan_json.get("visit") or {}) if stored is not None else {}
    return plans, summaries


def measure_inputs(c: Campaign, label: str, params: dict, plan_hash: str | None = None, setup: int = 1) -> str:
    """Stage 1's input hash of an epoch (set-up) with fine scans (``plan_hash`` when already computed)."""
    inp = c.epoch_inputs(label, plan=False, setup=setup)
    if plan_hash is None:
        plan_hash = _plan_hashes(c, label, setup, inp, params)[2]
    return _measure_hash(inp, plan_hash)


def measure_epoch(c: Campaign, label: str, *, setup: int = 1, progress: ProgressCallback | None = None) -> dict:
    """Plan (when needed) and centroids of an epoch's set-up with fine scans, saved; returns the centroids."""
    job = stage1_job(c, label, setup)
    if not job.fine_paths:
        where = f"set-up {setup} of epoch {label}" if setup != 1 else f"epoch {label}"
        raise ProcessingError(f"{where} has no fine scans yet; import them with 'bridgesurvey add-fine' first")
    result = run_stage1(job, progress=progress)
    save_stage1(c, result)
    return result.centroids or {}


def _stale_reason(inp: EpochInputs, params: dict, plan_hash: str) -> str | None:
    """Why one set-up's stored stage-1 result no longer matches its inputs (None: up to date)."""
    res = inp.result
    if not inp.coarse:
        return None
    if inp.fine:
        want = _measure_hash(inp, plan_hash)
        if res is None or res.stage != "measured":
            return "not measured yet"
        if res.inputs_hash != want:
            if res.inputs_hash in (_measure_hash(inp, plan_hash, version=v) for v in ("1", "2", "3")):
                return "centroid estimate updated"
            return "inputs or parameters changed"
        return None
    want = plan_hash
    if res is None:
        return "not planned yet"
    if res.inputs_hash != want and res.stage == "planned":
        return "inputs or parameters changed"
    return None


def _stale_setups(c: Campaign, label: str, params: dict, inputs: Mapping[int, EpochInputs] | None = None, *,
                  previews: bool = True) -> dict[int, str]:
    """The set-ups of an epoch whose stage-1 results are stale: set-up -> reason (``inputs``: its set-ups' inputs).

    With ``previews`` a set-up whose map preview is damaged is stale too (planned again, which remakes it:
    :meth:`~projects.store.campaign.Campaign.preview_to_remake`); the quick looks leave previews unread.
    """
    if inputs is None:
        first = c.epoch_inputs(label, plan=False)  # one read an epoch (more for further set-ups)
        inputs = {k: first if k == 1 else c.epoch_inputs(label, plan=False, setup=k) for k in first.setups}
    own = {k: _plan_hash(inp, params) for k, inp in inputs.items() if inp.coarse}
    together = len(own) > 1 and params.get("plan_together", True)
    out = {}
    for k, inp in inputs.items():
        if not inp.coarse:
            continue
        frozen = _frozen_hash(c, label, inp, own[k]) if len(own) > 1 else None  # alone or together
        h = frozen or _visit_hash(own[k], {j: own[j] for j in own if j != k} if together else {}, params)
        why = _stale_reason(inp, params, h)
        if why is None and previews and c.preview_to_remake(label, k):
            why = PREVIEW_DAMAGED
        if why is not None:
            out[k] = why
    return out


def stale_epochs(c: Campaign) -> dict[str, str]:
    """Epochs whose stored stage-1 results (of any set-up) no longer match their inputs: label -> reason.

    The quick look of ``status`` and the application: the map previews are not read (``process`` also plans
    again an epoch whose preview is damaged, and says so; ``verify`` names it).
    """
    params = parameters(c)
    out = {}
    for label, inputs in c.visits_inputs().items():  # one read for all (the campaign's rows once)
        stale = _stale_setups(c, label, params, inputs, previews=False)
        if stale:
            out[label] = "; ".join(why if k == 1 else f"set-up {k}: {why}" for k, why in sorted(stale.items()))
    return out


def baseline_epoch(c: Campaign) -> str | None:
    """The baseline epoch: the one chosen, else the first measured one (None before any)."""
    chosen = c.settings().get("baseline")
    if chosen:
        return chosen
    for e in c.epochs():
        if _stage1_hash(c, e.label):
            return e.label
    return None


def process(c: Campaign, labels: Sequence[str] | None = None, *,
            progress: ProgressCallback | None = None) -> ProcessSummary:
    """Bring the given epochs (default: all) up to date, then their displacements."""
    epochs = c.epochs()
    if labels:
        for lab in labels:
            c.epoch(lab)
        wanted = set(labels)
        todo = [e for e in epochs if e.label in wanted]
    else:
        todo = epochs
    summary = ProcessSummary()
    params = parameters(c)
    for k, e in enumerate(todo):
        lab = e.label
        sub = scaled(progress, k / max(len(todo), 1), (k + 1) / max(len(todo), 1))
        stale = _stale_setups(c, lab, params)
        if not stale:
            summary.outcomes.append(EpochOutcome(lab, "up-to-date"))
            continue
        summary.outcomes.append(_process_setups(c, lab, sorted(stale), sub))
    finish_displacements(c, summary, [e.label for e in todo])
    report(progress, 1.0, "done")
    return summary


def _process_setups(c: Campaign, lab: str, setups: Sequence[int], progress) -> EpochOutcome:
    """Plan or measure the given set-ups of an epoch; one outcome for the epoch (a set-up's failure in its message)."""
    actions, notes, archived = [], [], []
    for n, k in enumerate(setups):
        sub = scaled(progress, n / len(setups), (n + 1) / len(setups))
        where = "" if k == 1 and len(setups) == 1 else f"set-up {k}: "
        try:
            if c.files(lab, "fine", setup=k):
                cents = measure_epoch(c, lab, setup=k, progress=sub)
                found = sum(t.found for t in cents.values())
                actions.append("measured")
                notes.append(f"{where}{found}/{len(cents)} targets found")
            else:
                plan = plan_epoch(c, lab, setup=k, progress=sub)
                actions.append("planned")
                notes.append(f"{where}{len(plan.rois)} windows, {plan.total_seconds / 60:.1f} min; add its fine scans")
        except CancelledError:
            raise  # the user stopped the whole run, not this epoch (the epochs done so far are kept)
        except SurveyError as exc:
            c.check_still_there()  # a folder moved while processing: one line for the run, not one per epoch
            log.warning("epoch %s%s: %s", lab, f" set-up {k}" if k != 1 else "", exc)
            actions.append("failed")
            archived.append(isinstance(exc, ScansArchivedError))
            notes.append(f"{where}{exc}")
    action = "failed" if "failed" in actions else "measured" if "measured" in actions else "planned"
    return EpochOutcome(lab, action, "; ".join(notes), archived=bool(archived) and all(archived))


def finish_displacements(c: Campaign, summary: ProcessSummary, labels: Sequence[str]) -> None:
    """Stage 2 after stage 1: fix the baseline once, update the displacements, note the problems of ``labels``."""
    summary.baseline = baseline_epoch(c)
    if summary.baseline is not None and not c.settings().get("baseline"):
        # The first measured epoch becomes the baseline once, for good: an epoch added later with an
        # earlier date gets a negative time against it instead of silently re-referencing everything.
        c.set_setting("baseline", summary.baseline)
    if summary.baseline is not None:
        summary.displacement_epochs = update_displacements(c, summary.baseline, reasons=summary.displacement_reasons)
    for lab in labels:
        ds = c.displacement_set(lab)
        if ds is not None:
            bad = [f for f in ds.flags if severity(f) == PROBLEM]
            if bad:
                summary.problems[lab] = bad[0]


def _stage1_hash(c: Campaign, label: str) -> str | None:
    """The stage-1 hash of a measured epoch (None when set-up 1 is not measured); of every set-up with several."""
    res = c.result(label)
    if res is None or res.stage != "measured":
        return None
    setups = c.setups(label)
    if setups == [1]:
        return res.inputs_hash
    others = [(k, r.inputs_hash if (r := c.result(label, k)) is not None and r.stage == "measured" else None)
              for k in setups[1:]]
    return _hash([res.inputs_hash, others])


def _measured_setups(c: Campaign, label: str) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(every set-up, the measured ones) of an epoch: set-up 1 always counts as measured."""
    every = c.setups(label)
    return tuple(every), tuple(k for k in every if k == 1 or ((r := c.result(label, k)) is not None
                                                            and r.stage == "measured"))


def _air_series(c: Campaign, records: Sequence) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The air series ``records`` (temperature, pressure, humidity) as (kind, times ns, values)."""
    return [(r.kind, *series_arrays_from_npz(c.series.arrays("env_series", r.name))) for r in records]


def _air_records(c: Campaign) -> list:
    """The environment series stage 2 reads (the air: temperature, pressure, humidity)."""
    return [r for r in c.series.records("env_series") if r.kind in ("temperature", "pressure", "humidity")]


def _reflectors_key(refl: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in refl.items()))


def stale_displacements(c: Campaign) -> dict[str, str]:
    """Measured epochs whose stored displacements ``process`` would recompute for a known reason: label -> why.

    Told without fitting anything, from the input parts each visit's displacements were computed with
    (:func:`lidar.stage2.input_parts`): an imported air series, a changed setting, reflector or baseline, new
    centroids. A measured epoch without displacements is stale too. What a re-fitted field model will change
    is not known before it is fitted: processing lists it as revisions.
    """
    base = baseline_epoch(c)
    if base is None:
        return {}
    params = parameters(c)
    base_digest = _stage1_hash(c, base) or ""
    now = {"baseline": f"{base}:{base_digest[:16]}", "settings": inputs_digest(dict(stage2_params(params)))[:16],
           "reflectors": inputs_digest(list(_reflectors_key({r.id: r for r in c.reflectors()})))[:16],
           "air": inputs_digest(list(sorted(r.sha256 for r in _air_records(c))))[:16]}
    out = {}
    for e in c.epochs():
        digest = _stage1_hash(c, e.label)
        if not digest:
            continue
        if c.displacement_set(e.label) is None:
            out[e.label] = "displacements not computed yet"
            continue
        stored = c.systematics(e.label).get("inputs")
        if stored:  # visits processed before the parts were recorded: nothing known
            why = stale_parts(stored, {**now, "centroids": digest[:16]})
            if why:
                out[e.label] = "; ".join(why)
    return out


def skipped_rescans(verdict) -> dict[str, str]:
    """The re-scans a check asked for and the user processed without: ``target -> why`` (``*``: the set-up turned).

    Empty without a check, when it asked for none, or while it is still pending (the visit is not processed then).

    >>> from projects.store.records import CheckVerdict
    >>> skipped_rescans(CheckVerdict("e", "t", ("M3",), {"M3": "211 of 1036 planned points"}, accepted=True))
    {'M3': '211 of 1036 planned points'}
    >>> skipped_rescans(CheckVerdict("e", "t", ("M3",), {"M3": "not found"})), skipped_rescans(None)
    ({}, {})
    """
    if verdict is None or not verdict.accepted:
        return {}
    out = {t: verdict.reasons.get(t, "re-scan asked") for t in verdict.rescan}
    if verdict.drifted:
        out["*"] = "the closure showed the set-up turned beyond the instrument's tolerance"
    return out


def stage2_inputs(c: Campaign, baseline: str) -> Stage2Inputs:
    """Everything stage 2 needs of the campaign, read in one snapshot (see :class:`lidar.stage2.Stage2Inputs`)."""
    with c.snapshot():
        params = parameters(c)
        refl = {r.id: r for r in c.reflectors()}
        epochs = c.epochs()
        order = {e.label: n for n, e in enumerate(epochs)}
        air_records = _air_records(c)
        series = _air_series(c, air_records)
        verdicts = c.check_verdicts()  # one read of the log, not one an epoch
        visits = []
        for e in epochs:
            digest = _stage1_hash(c, e.label)
            if not digest:
                continue
            every, measured = _measured_setups(c, e.label)
            air = air_near(series, int(e.when.timestamp() * 1e9)) if series else None
            visits.append(VisitInputs(
                e.label, digest, every, measured, {k: c.centroids(e.label, k) for k in every},
                {k: c.closure_centroids(e.label, k) for k in measured},
                {k: c.time_source(e.label, k) or "none" for k in measured}, air,
                c.profile_for(e.label).wavelength_nm, skipped_rescans(verdicts.get(e.label))))
        stored = c.field_model()
        stored_digests = {v.label: ds.inputs_hash for v in visits if (ds := c.displacement_set(v.label)) is not None}
        replaced = {r.replaces for r in refl.values() if r.replaces}
        rows = c.displacements() if replaced else []  # one read, not one a replaced target
        history = {old: tuple(StoredDisplacement(d.epoch, order[d.epoch], float(d.displacement_m), float(d.sigma_m))
                              for d in rows if d.reflector == old and d.displacement_m is not None
                              and d.sigma_m is not None and d.epoch in order)
                   for old in replaced}
    return Stage2Inputs(baseline, tuple(visits), {rid: r.group for rid, r in refl.items()},
                        {rid: r.replaces for rid, r in refl.items() if r.replaces},
                        _reflectors_key(refl), params, stage2_params(params),
                        tuple(sorted(r.sha256 for r in air_records)), None if stored is None else stored[0],
                        stored_digests, history, order)


def update_displacements(c: Campaign, baseline: str, *, reasons: dict | None = None) -> list[str]:
    """(Re)compute the displacements of every measured epoch whose inputs changed; returns those epochs.

    Stage 2 is a pure job (:func:`lidar.stage2.run_stage2`) on one snapshot of the campaign
    (:func:`stage2_inputs`): the campaign's field model is fitted first over every measured epoch (every set-up
    of one, as a visit of its own), then each changed epoch's displacements. What it computed is stored in one
    transaction. ``reasons`` (epoch -> ``"field"``, ``"inputs"`` or ``"new"``) says why each was recomputed.
    """
    why = stale_displacements(c)
    inputs = stage2_inputs(c, baseline)
    if baseline not in [v.label for v in inputs.visits]:
        return []
    result = run_stage2(inputs)
    revised = []
    again = [e for e in result.epochs if e.reason != "new"]
    if again:  # what was stored (and perhaps reported) and changes now: never silent
        stored: dict[str, dict] = {e.label: {} for e in again}
        for d in c.displacements():
            if d.epoch in stored:
                stored[d.epoch][d.reflector] = (d.displacement_m, d.sigma_m, d.flags)
        for e in again:
            because = FIELD_REFIT if e.reason == "field" else why.get(e.label) or "its inputs changed"
            revised += revisions(e.label, stored[e.label], e.displacements, because)
    c.save_stage2(baseline, result.model if result.model_changed else None, result.epochs,
                  revisions=[r.to_json() for r in revised])
    if reasons is not None:
        reasons.update({e.label: e.reason for e in result.epochs if e.reason != "new"})
    return result.labels


def save_edited_plan(c: Campaign, label: str, plan: ScanPlan) -> None:
    """Store a plan whose windows were edited by hand; it replaces the epoch's plan and its centroids.

    The plan keeps the inputs hash of the plan it was edited from, so processing uses it as it is
    (and measures the epoch again when fine scans exist); a new coarse scan, layout or parameter
    plans the epoch afresh.
    """
    stored = c.stored_plan(label)
    if stored is None:
        raise ProcessingError(f"epoch {label} has no plan to edit yet; plan it first")
    if not plan.rois:
        raise InputError("the edited plan has no windows; keep at least one")
    old = stored.plan_json
    d = plan.to_json()
    d["epoch"] = label
    d["edited"] = True
    for key in ("identification", "candidates", "own_inputs", "visit"):  # what the coarse scan and the visit said
        if key in old:
            d[key] = old[key]
    c.save_plan(label, d, stored.inputs_hash)

"""Stage 2 of processing as a pure job: the campaign's field model and every visit's displacements.

Stage 1 (per visit) turns scans into centroids. Stage 2 takes the centroids of every measured visit at once,
because the campaign's field model (:mod:`lidar.systematic`: the atmosphere's scale per visit, the
retro-reflector range walk, the set-up's drift, the instrument's axis errors) is fitted over all of them; then
each visit's set-ups are corrected and joined (:mod:`lidar.setups`) and its displacements computed against the
baseline with their error budget (:mod:`lidar.systematic.budget`) and flags.

Everything it needs is one value, :class:`Stage2Inputs` (read by the campaign's owner in one snapshot), and
:func:`run_stage2` returns the field model, each changed visit's displacements with their flags, budget and
inputs digest: no database, no files. A visit whose digest equals the stored one (its centroids, its
baselines', the parameters, the reflectors, the air series and the field model's terms it depends on) is not
recomputed, so adding a visit computes that visit (and all of them only when the model changed materially).

Examples
--------
A campaign of two visits of a simulated bridge, processed without a database::

    inputs = Stage2Inputs(baseline="e1", visits=(VisitInputs("e1", ...), VisitInputs("e2", ...)), groups=...)
    result = run_stage2(inputs)
    result.epoch("e2").displacements.of("M3").displacement_m
"""
from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from common.errors import ProcessingError, SurveyError
from common.flags import (
    FLAG_CHAINED,
    FLAG_DECK_NOT_MEASURED,
    FLAG_FIELD_MISFIT,
    FLAG_MISSING,
    FLAG_NO_DISPLACEMENT,
    FLAG_NOT_FOUND,
    FLAG_PIER_MOVED,
    FLAG_PIERS_NOT_MEASURED,
    FLAG_RESCAN_SKIPPED,
    FLAG_SETUP_NOT_MEASURED,
    FLAG_UNRESOLVED,
    PROBLEM,
    WARNING,
    code,
    has,
    in_baseline,
    severity,
    words,
    worst,
)
from lidar.centroid import TargetCentroid
from lidar.displacement_result import Displacement, EpochDisplacements
from lidar.setups import CorrectedVisit, corrected_side, joined_displacements, visit_label, without_weak_duplicates
from lidar.systematic.adjustment import FieldModel
from lidar.systematic.budget import corrected_displacements
from lidar.systematic.campaign_fit import (
    Air,
    air_scale_ppm,
    atmosphere_flags,
    epoch_flags,
    refit,
    systematics_json,
    visit_digest,
)

log = logging.getLogger(__name__)

#: Version of stage 2's computation, in every visit's inputs digest (2: a disc straddling a strength step of the
#: range walk carries the step it may straddle in its covariance, lidar.systematic.range_walk.RangeWalkModel.smear_m).
STAGE2_VERSION = "2"


def inputs_digest(obj: Any) -> str:
    """A digest of a JSON-able value (keys sorted; other values by their ``str``), 32 hex digits.

    Examples
    --------
    >>> inputs_digest({"b": 1, "a": [1, 2]}) == inputs_digest({"a": [1, 2], "b": 1})
    True
    """
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:32]


@dataclass(frozen=True, eq=False)
class VisitInputs:
    """What stage 2 reads of one measured visit (an epoch, with all its set-ups).

    Attributes
    ----------
    label : str
        The epoch.
    stage1_digest : str
        Its stage-1 results' digest (every set-up's): a change re-computes its displacements.
    setups : tuple of int
        Every set-up of the visit (1 first).
    measured : tuple of int
        The set-ups with measured centroids (set-up 1 always counts as measured).
    centroids : mapping set-up -> (mapping target -> TargetCentroid)
        Every centroid of each set-up, found or not (empty for a set-up without fine scans).
    closures : mapping set-up -> (mapping target -> TargetCentroid)
        The closure windows' centroids (a target scanned again at the end of a set-up).
    time_sources : mapping set-up -> str
        How the centroids' times were had: ``"points"`` (point times), ``"plan"`` or ``"none"``.
    air : (float, float, float) or None
        Temperature degC, pressure hPa and relative humidity 0..1 around the visit (None without a temperature).
    wavelength_nm : float
        The scanner's wavelength (for the atmosphere's scale).
    rescan : mapping target -> str
        The targets the check before leaving asked to re-scan, when the visit was processed without the re-scan
        (``process --accept-check``), with why; ``*`` for the whole set-up (it turned). Their rows say so
        (:data:`common.flags.FLAG_RESCAN_SKIPPED`).
    """

    label: str
    stage1_digest: str
    setups: tuple[int, ...]
    measured: tuple[int, ...]
    centroids: Mapping[int, Mapping[str, TargetCentroid]]
    closures: Mapping[int, Mapping[str, TargetCentroid]] = field(default_factory=dict)
    time_sources: Mapping[int, str] = field(default_factory=dict)
    air: Air | None = None
    wavelength_nm: float = 1550.0
    rescan: Mapping[str, str] = field(default_factory=dict)

    @property
    def unmeasured(self) -> tuple[int, ...]:
        return tuple(k for k in self.setups if k not in self.measured)

    @property
    def several(self) -> bool:
        """Whether the visit has (or should have had) more than one set-up."""
        return len(self.measured) > 1 or bool(self.unmeasured)

    def found_setup(self, setup: int) -> dict[str, TargetCentroid]:
        return {k: v for k, v in self.centroids.get(setup, {}).items() if v.found}

    def found(self) -> dict[str, TargetCentroid]:
        """Every target found in any set-up of the visit (set-up 1's centroid first)."""
        out: dict[str, TargetCentroid] = {}
        for k in self.measured:
            for t, v in self.found_setup(k).items():
                out.setdefault(t, v)
        return out


@dataclass(frozen=True)
class StoredDisplacement:
    """A displacement already stored, as chaining a replaced target's history needs it (metres)."""

    epoch: str
    order: int  # the epoch's place in the campaign's date order
    displacement_m: float
    sigma_m: float


@dataclass(frozen=True, eq=False)
class Stage2Inputs:
    """Everything stage 2 needs, as plain values (one snapshot of a campaign).

    Attributes
    ----------
    baseline : str
        The baseline epoch (a measured visit).
    visits : tuple of VisitInputs
        Every measured visit, in date order.
    groups : mapping target -> "reference" | "measurement"
    replaces : mapping target -> str
        A target that replaced another: the one it replaced (its history continues).
    reflectors_key : tuple
        The reflectors as they enter the digests (a change of one re-computes every visit).
    params : mapping
        The processing parameters stage 2 reads: ``field_model`` (bool), ``normal_mode``,
        ``moved_tolerance_m`` (m) and ``weighted_references`` (see :mod:`projects.processing.parameters`);
        ``digest_params`` those that enter the digests.
    digest_params : mapping
    air_key : tuple of str
        The digests of the air's series (a new one can change the atmosphere's flags).
    stored_model : FieldModel or None
        The field model stored by the last run.
    stored_digests : mapping epoch -> str
        Each visit's stored displacements' inputs digest.
    history : mapping target -> tuple of StoredDisplacement
        The stored displacements of targets that others replaced.
    order : mapping epoch -> int
        Every epoch's place in the campaign's date order (measured or not).
    """

    baseline: str
    visits: tuple[VisitInputs, ...]
    groups: Mapping[str, str]
    replaces: Mapping[str, str] = field(default_factory=dict)
    reflectors_key: tuple = ()
    params: Mapping[str, Any] = field(default_factory=dict)
    digest_params: Mapping[str, Any] = field(default_factory=dict)
    air_key: tuple[str, ...] = ()
    stored_model: FieldModel | None = None
    stored_digests: Mapping[str, str] = field(default_factory=dict)
    history: Mapping[str, tuple[StoredDisplacement, ...]] = field(default_factory=dict)
    order: Mapping[str, int] = field(default_factory=dict)

    def visit(self, label: str) -> VisitInputs:
        for v in self.visits:
            if v.label == label:
                return v
        raise ProcessingError(f"epoch {label} is not a measured visit of this campaign")


@dataclass(frozen=True, eq=False)
class EpochDisplacementResult:
    """One visit's displacements as stage 2 computed them.

    ``reason`` says why it was computed: ``"new"`` (nothing stored), ``"inputs"`` (its centroids, its
    baselines', the parameters or the reflectors changed) or ``"field"`` (only the field model's terms moved).
    """

    label: str
    displacements: EpochDisplacements
    systematics: dict
    inputs_hash: str
    reason: str


@dataclass(frozen=True, eq=False)
class Stage2Result:
    """What :func:`run_stage2` computed: the field model and the visits whose displacements changed."""

    model: FieldModel
    model_changed: bool
    epochs: tuple[EpochDisplacementResult, ...]

    @property
    def labels(self) -> list[str]:
        return [e.label for e in self.epochs]

    def epoch(self, label: str) -> EpochDisplacementResult:
        for e in self.epochs:
            if e.label == label:
                return e
        raise ProcessingError(f"epoch {label}'s displacements were not computed in this run")


class _Visits:
    """The visits' centroids as the field model and the joins see them (set-ups as visits ``L#k``)."""

    def __init__(self, inputs: Stage2Inputs, model: FieldModel | None = None):
        self.inputs = inputs
        self.by_label = {v.label: v for v in inputs.visits}
        self.setup_visits = {visit_label(v.label, k): (v.label, k) for v in inputs.visits for k in v.measured}
        self._sides: dict[str, CorrectedVisit] = {}
        self.model = model

    def found(self, label: str) -> dict[str, TargetCentroid]:
        return self.by_label[label].found()

    def found_setup_visit(self, visit: str) -> dict[str, TargetCentroid]:
        lab, k = self.setup_visits[visit]
        return self.by_label[lab].found_setup(k)

    def closures_setup_visit(self, visit: str) -> Mapping[str, TargetCentroid]:
        lab, k = self.setup_visits[visit]
        return self.by_label[lab].closures.get(k, {})

    def several(self, label: str) -> bool:
        return self.by_label[label].several

    def side(self, label: str) -> CorrectedVisit:
        if label not in self._sides:
            v = self.by_label[label]
            assert self.model is not None
            self._sides[label] = corrected_side(label, {k: v.found_setup(k) for k in v.measured}, self.model)
        return self._sides[label]

    def key(self, labels: Sequence[str]) -> dict:
        """What the displacements of visits with several set-ups also depend on: each set-up's field-model terms."""
        assert self.model is not None
        return {lab: {"measured": {str(k): visit_digest(self.model, visit_label(lab, k), visit_label(lab, k))
                                   for k in self.by_label[lab].measured},
                      "unmeasured": list(self.by_label[lab].unmeasured)}
                for lab in labels if self.several(lab)}

    def displacements(self, b: str, lab: str, groups: Mapping[str, str]) -> EpochDisplacements:
        """One visit's displacements against ``b``, joining set-ups when either has several."""
        p = self.inputs.params
        options = {"normal_mode": p["normal_mode"], "moved_tolerance_m": p["moved_tolerance_m"],
                   "weighted": bool(p["weighted_references"])}
        assert self.model is not None
        if not self.several(b) and not self.several(lab):
            return corrected_displacements(self.found(b), self.found(lab), groups, model=self.model,
                                           baseline_label=b, epoch_label=lab, **options)
        return joined_displacements(self.side(b), self.side(lab), groups, model=self.model, **options)


#: What each part of a visit's stored ``inputs`` means when it no longer matches (``status`` says it before processing).
INPUT_PARTS = {"centroids": "its centroids changed", "baseline": "the baseline changed",
               "settings": "a processing setting changed", "reflectors": "the reflectors changed (added, retired or "
               "replaced)", "air": "the air series changed (imported or removed)"}


def input_parts(inputs: Stage2Inputs, stage1_digest: str, baseline_digest: str) -> dict[str, str]:
    """A visit's stage-2 inputs by part, each a short digest (stored in its systematics as ``inputs``).

    Whether a stored visit is out of date can then be told part by part without fitting anything
    (:data:`INPUT_PARTS` says what each means); the field model, fitted at processing, is not among them.
    """
    return {"centroids": stage1_digest[:16], "baseline": f"{inputs.baseline}:{baseline_digest[:16]}",
            "settings": inputs_digest(dict(inputs.digest_params))[:16],
            "reflectors": inputs_digest(list(inputs.reflectors_key))[:16],
            "air": inputs_digest(list(inputs.air_key))[:16]}


def stale_parts(stored: Mapping[str, str], now: Mapping[str, str]) -> list[str]:
    """What changed between a visit's stored input parts and today's, in words (empty: nothing known changed).

    >>> stale_parts({"air": "a1", "settings": "s"}, {"air": "a2", "settings": "s"})
    ['the air series changed (imported or removed)']
    """
    return [INPUT_PARTS[k] for k in INPUT_PARTS if k in stored and k in now and stored[k] != now[k]]


#: A stored value is revised when processing moves it by at least this share of its stored sigma (or it appears,
#: disappears, or its row's most serious flag changes severity).
REVISION_SIGMAS = 0.5


@dataclass(frozen=True)
class Revision:
    """A value or state already stored (and perhaps reported) that processing changed.

    Attributes
    ----------
    epoch, target : str
    old, new : str
        The value as the report printed it: ``-2.10 ± 0.10 mm`` and the row's most serious flag in words, or
        ``no value``.
    why : str
        What made processing recompute it.
    """

    epoch: str
    target: str
    old: str
    new: str
    why: str

    def line(self) -> str:
        return f"{self.epoch} {self.target}: {self.old} → {self.new} ({self.why})"

    def to_json(self) -> dict:
        return {"epoch": self.epoch, "target": self.target, "old": self.old, "new": self.new, "why": self.why}


def _said(d_m: float | None, s_m: float | None, flags: Sequence[str]) -> str:
    level = worst(flags)
    serious = [f for f in flags if severity(f) == level] if level in (WARNING, PROBLEM) else []
    value = "no value" if d_m is None or not np.isfinite(d_m) else \
        f"{d_m * 1e3:+.2f} ± {(s_m or 0.0) * 1e3:.2f} mm"
    return value + (f" ({level}: {words(serious[0])})" if serious else "")


def _loud(flags: Sequence[str]) -> str | None:
    """The most serious severity when it asks the surveyor to act (warning, problem), else None."""
    level = worst(flags)
    return level if level in (WARNING, PROBLEM) else None


def revisions(label: str, stored: Mapping[str, tuple[float | None, float | None, Sequence[str]]],
              new: EpochDisplacements, why: str) -> list[Revision]:
    """The stored values of one visit that ``new`` changes beyond :data:`REVISION_SIGMAS` or in severity.

    Parameters
    ----------
    label : str
        The visit.
    stored : mapping target -> (displacement m or None, sigma m or None, flags)
        Its rows as stored before this run.
    new : EpochDisplacements
        What processing computed for it now.
    why : str
        What made processing recompute it, in words.
    """
    out = []
    for d in new.displacements:
        if d.reflector not in stored:
            continue
        old_d, old_s, old_f = stored[d.reflector]
        had = old_d is not None and np.isfinite(old_d)
        has_ = np.isfinite(d.displacement_m)
        moved = had and has_ and abs(d.displacement_m - float(old_d or 0.0)) >= max(REVISION_SIGMAS * (old_s or 0.0),
                                                                                    1e-5)
        if had != has_ or moved or _loud(old_f) != _loud(d.flags):
            out.append(Revision(label, d.reflector, _said(old_d, old_s, old_f),
                                _said(float(d.displacement_m), float(d.sigma_m), d.flags), why))
    return out


def _first_seen(inputs: Stage2Inputs, vs: _Visits) -> dict[str, str]:
    """Each target's first visit from the baseline on (a target installed later is referred to it)."""
    labels = [v.label for v in inputs.visits]
    first: dict[str, str] = {}
    for lab in labels[labels.index(inputs.baseline):]:
        for rid in vs.found(lab):
            first.setdefault(rid, lab)
    return first


def _bases(inputs: Stage2Inputs, vs: _Visits, lab: str, first_seen: Mapping[str, str]) -> list[str]:
    """The visits ``lab``'s displacements are referred to: the baseline, and the first visits of later targets."""
    labels = [v.label for v in inputs.visits]
    if labels.index(lab) < labels.index(inputs.baseline):  # dated before the baseline: negative time against it
        return [inputs.baseline]
    groups = inputs.groups
    meas_here = [m for m in vs.found(lab) if groups.get(m) == "measurement"]
    return sorted({first_seen[m] for m in meas_here} | {inputs.baseline}, key=labels.index)


def _core_digest(inputs: Stage2Inputs, vs: _Visits, lab: str, bases: Sequence[str]) -> str:
    """The digest of a visit's inputs apart from the field model (its centroids, its bases', the settings...)."""
    key: dict[str, Any] = {"v": "1", "epoch": vs.by_label[lab].stage1_digest, "params": dict(inputs.digest_params),
                           "bases": {b: vs.by_label[b].stage1_digest for b in bases},
                           "reflectors": list(inputs.reflectors_key), "air": list(inputs.air_key)}
    if vs.by_label[lab].rescan:  # only then: the digests of visits without one stay as they were
        key["rescan"] = sorted(vs.by_label[lab].rescan.items())
    return inputs_digest(key)


def frozen_visits(inputs: Stage2Inputs) -> set[str]:
    """The visits the field model's window leaves out whose stored values stand (``field_window``).

    The model is fitted over the baseline and the newest ``field_window`` measured visits (0: all); an older
    visit keeps the displacements computed while it was among them, as long as its own inputs (apart from the
    model) are unchanged. One whose inputs changed (a setting, the air, a reflector) is not frozen: the model
    is then fitted over every visit again, so it can be recomputed.
    """
    window = int(inputs.params.get("field_window", 0) or 0)
    labels = [v.label for v in inputs.visits]
    if not window or len(labels) <= window + 1:
        return set()
    vs = _Visits(inputs)
    first_seen = _first_seen(inputs, vs)
    newest = set(labels[-window:]) | {inputs.baseline}
    frozen = set()
    for lab in labels:
        if lab in newest:
            continue
        stored = inputs.stored_digests.get(lab)
        if stored is None or stored.split(":")[0] != _core_digest(inputs, vs, lab, _bases(inputs, vs, lab,
                                                                                            first_seen)):
            return set()  # an old visit to compute again: fit over every visit
        frozen.add(lab)
    return frozen


def fit_model(inputs: Stage2Inputs, *, leave_out: set[str] | None = None) -> FieldModel:
    """The campaign's field model over the measured visits' set-ups (the stored one kept while it holds).

    ``leave_out``: visits not fitted (default :func:`frozen_visits`, those the ``field_window`` leaves out).
    """
    leave_out = frozen_visits(inputs) if leave_out is None else leave_out
    vs = _Visits(inputs)
    groups = dict(inputs.groups)
    fitted = [sv for sv, (lab, _) in vs.setup_visits.items() if lab not in leave_out]
    base_air = vs.by_label[inputs.baseline].air if inputs.baseline in vs.by_label else None
    air = {}
    for sv in fitted:
        v = vs.by_label[vs.setup_visits[sv][0]]
        if v.air is not None and base_air is not None:
            air[sv] = air_scale_ppm(v.air, base_air, wavelength_nm=v.wavelength_nm)
    return refit(inputs.stored_model, inputs.baseline, fitted, groups, vs.found_setup_visit,
                 vs.closures_setup_visit, enabled=bool(inputs.params.get("field_model", True)), air_scale=air)


def run_stage2(inputs: Stage2Inputs, *, model: FieldModel | None = None) -> Stage2Result:
    """Fit the field model and compute the displacements of every visit whose inputs changed.

    Parameters
    ----------
    inputs : Stage2Inputs
        One snapshot of the campaign (see :func:`projects.processing.stages.stage2_inputs`).
    model : FieldModel, optional, keyword-only
        A field model already fitted on these inputs (default: fitted here, :func:`fit_model`).

    Returns
    -------
    Stage2Result
        The model (``model_changed``: it differs from the stored one) and each recomputed visit's
        displacements, flags, systematics and inputs digest, in date order.
    """
    labels = [v.label for v in inputs.visits]
    baseline = inputs.baseline
    if baseline not in labels:
        raise ProcessingError(f"the baseline {baseline} is not a measured epoch")
    frozen = frozen_visits(inputs)
    if model is None:
        model = fit_model(inputs, leave_out=frozen)
    changed = inputs.stored_model is None or model.digest() != inputs.stored_model.digest()
    vs = _Visits(inputs, model)
    first_seen = _first_seen(inputs, vs)
    history = {t: list(rows) for t, rows in inputs.history.items()}
    out = []
    for pos, lab in enumerate(labels):
        if lab in frozen:  # left out of the model's window, its inputs unchanged: its stored values stand
            continue
        bases = _bases(inputs, vs, lab, first_seen)
        field_key: dict = {b: visit_digest(model, b, lab) for b in bases}
        if any(vs.several(x) for x in [*bases, lab]):
            field_key["setups"] = vs.key(sorted({*bases, lab}))
        core = _core_digest(inputs, vs, lab, bases)
        h = f"{core}:{inputs_digest(field_key)}"
        stored = inputs.stored_digests.get(lab)
        if stored == h:
            continue
        reason = "new" if stored is None else "field" if stored.split(":")[0] == core else "inputs"
        result = _epoch_displacements(inputs, vs, lab, bases, first_seen, history)
        if result is None:
            continue
        v = vs.by_label[lab]
        flags, systematics = _setup_terms(vs, lab, epoch_flags(model, lab, v.time_sources.get(1, "none")),
                                          systematics_json(model, lab, v.time_sources.get(1, "none")))
        systematics["inputs"] = input_parts(inputs, v.stage1_digest, vs.by_label[baseline].stage1_digest)
        air = atmosphere_flags(model, lab, v.air, vs.by_label[baseline].air, wavelength_nm=v.wavelength_nm)
        result = replace(result, flags=tuple(result.flags) + tuple(flags) + tuple(air))
        moved = tuple(f for f in air if f.startswith(FLAG_PIER_MOVED + ":"))
        if moved:  # every value of the visit is against a pier that moved: its rows say so too
            result = replace(result, displacements=tuple(replace(d, flags=tuple(d.flags) + moved)
                                                         for d in result.displacements))
        if v.rescan:
            result = _with_rescan_skipped(result, v.rescan, dict(inputs.groups))
        out.append(EpochDisplacementResult(lab, result, systematics, h, reason))
        for d in result.displacements:  # a later visit's chain reads this run's values
            if d.reflector in history:
                rows = [r for r in history[d.reflector] if r.epoch != lab]
                if np.isfinite(d.displacement_m):
                    rows.append(StoredDisplacement(lab, inputs.order.get(lab, pos), float(d.displacement_m),
                                                   float(d.sigma_m)))
                history[d.reflector] = rows
    return Stage2Result(model, changed, tuple(out))


def _with_rescan_skipped(result: EpochDisplacements, rescan: Mapping[str, str],
                         groups: Mapping[str, str]) -> EpochDisplacements:
    """Flag the rows of a visit processed without the re-scan its check asked for.

    The rows of the targets to re-scan, and every row when it was a reference target or the whole set-up (``*``),
    carry :data:`FLAG_RESCAN_SKIPPED` with the check's reason.

    >>> rows = (Displacement("M1", 0.0, 1e-4, 0.0, 0.0), Displacement("M2", 0.0, 1e-4, 0.0, 0.0))
    >>> r = EpochDisplacements(rows, (), (), np.zeros(3), np.zeros(3), "auto")
    >>> [d.flags for d in _with_rescan_skipped(r, {"M2": "not found"}, {"M2": "measurement"}).displacements]
    [(), ('rescan_skipped: not found',)]
    >>> [d.flags for d in _with_rescan_skipped(r, {"R1": "short"}, {"R1": "reference"}).displacements]
    [('rescan_skipped: R1: short',), ('rescan_skipped: R1: short',)]
    """
    every = [f"{t}: {why}" if t != "*" else why for t, why in sorted(rescan.items())
             if t == "*" or groups.get(t) == "reference"]
    rows = []
    for d in result.displacements:
        said = ([rescan[d.reflector]] if d.reflector in rescan else []) + every
        new = tuple(f"{FLAG_RESCAN_SKIPPED}: {w}" for w in said)
        rows.append(replace(d, flags=tuple(d.flags) + tuple(f for f in new if f not in d.flags)) if new else d)
    return replace(result, displacements=tuple(rows))


def _setup_terms(vs: _Visits, lab: str, flags: list, systematics: dict) -> tuple[list, dict]:
    """A visit's flags and systematics with its set-ups': their field-model flags, the join's flags and QA."""
    v = vs.by_label[lab]
    if not v.several:
        return flags, systematics
    assert vs.model is not None
    flags = list(flags)
    per_setup = {}
    for k in v.measured[1:]:
        sv = visit_label(lab, k)
        ts = v.time_sources.get(k, "none")
        flags += [f for f in epoch_flags(vs.model, sv, ts) if f not in flags]
        per_setup[str(k)] = systematics_json(vs.model, sv, ts)
    for k in v.unmeasured:
        flags.append(f"{FLAG_SETUP_NOT_MEASURED}: set-up {k} has no measured fine scans; the targets only it sees "
                     "are missing (import them with 'bridgesurvey add-fine --setup', then process)")
    try:
        join = vs.side(lab).join
    except SurveyError as exc:  # no set-up with a target: the visit's displacements already say why
        log.warning("epoch %s: %s", lab, exc)
        return flags, systematics
    flags += join.flags()
    return flags, {**systematics, "setups": {**join.to_json(), "systematics": per_setup}}


def _epoch_displacements(inputs: Stage2Inputs, vs: _Visits, lab: str, bases: list, first_seen: dict,
                         history: Mapping[str, list[StoredDisplacement]]) -> EpochDisplacements | None:
    """One visit's displacements against the baseline (and the later baselines of targets that replaced others)."""
    baseline, groups = inputs.baseline, dict(inputs.groups)
    cents = vs.found(lab)
    meas_here = [m for m in cents if groups.get(m) == "measurement"]
    base_deck = [m for m in vs.found(baseline) if groups.get(m) == "measurement"]
    if len(base_deck) < 3:  # nothing can be referred to this baseline: say so on every visit, with what to do
        n_meas = sum(1 for g in groups.values() if g == "measurement")
        return _failed_result(groups, vs.found(baseline), cents, baseline, "", flag=(
            f"{FLAG_DECK_NOT_MEASURED}: the baseline {baseline} measured {len(base_deck)} of {n_meas} deck targets, "
            "at least 3 needed: choose another baseline ('bridgesurvey settings DIR baseline LABEL') or re-scan it"))
    result = None
    extra: list = []
    failure = None
    for b in bases:
        targets = [m for m in meas_here if first_seen.get(m) == b] if b != baseline else \
            [m for m in groups if groups[m] == "measurement" and first_seen.get(m, baseline) == baseline]
        if not targets:
            continue
        sub_groups = {r: g for r, g in groups.items() if g == "reference" or r in targets}
        try:
            res = vs.displacements(b, lab, sub_groups)
        except SurveyError as exc:
            log.warning("epoch %s against %s: %s", lab, b, exc)
            if b == baseline:
                failure = str(exc).splitlines()[0].replace(";", ",")
            continue
        if b == baseline:
            result = res
        else:
            extra += [_chain(inputs, history, d, b) for d in res.displacements]
    if result is None:
        if failure is None:
            return None
        result = _failed_result(groups, vs.found(baseline), cents, baseline, failure)
    elif not any(np.isfinite(d.displacement_m) for d in result.displacements):
        n_meas = sum(1 for g in groups.values() if g == "measurement")
        result = replace(result, flags=tuple(result.flags) + (
            f"{FLAG_DECK_NOT_MEASURED}: none of the {n_meas} deck targets was found in this epoch",))
    if lab == baseline:  # the baseline against itself: zero by definition, exactly known
        result = replace(result, displacements=tuple(
            replace(d, displacement_m=0.0, sigma_m=0.0, along_m=0.0, along_sigma_m=0.0,
                    budget=dict.fromkeys(d.budget, 0.0)) if np.isfinite(d.displacement_m) else d
            for d in result.displacements))
    if extra:  # a target measured against a later baseline replaces its row against this one
        chained = {d.reflector for d in extra}
        result = replace(result, displacements=tuple(d for d in result.displacements if d.reflector not in chained)
                         + tuple(extra))
    v, vb = vs.by_label[lab], vs.by_label[baseline]
    assert vs.model is not None
    return with_field_misfits(vs.model, v.setups, vb.setups, lab, baseline, groups,
                               _with_centroid_doubts(v, vb, why_missing(v, result)))


def with_field_misfits(model: FieldModel, setups: Sequence[int], base_setups: Sequence[int], lab: str,
                        baseline: str, groups: Mapping[str, str], result: EpochDisplacements) -> EpochDisplacements:
    """Rows whose sightings the field model left out of its fit (in the visit or the baseline) say so.

    A sighting the adjustment down-weighted to nothing does not fit the model that corrects it: its corrected
    centroid may be off by more than the budget holds (a target whose range walk is not the campaign's: seen
    in simulation 4-6 sigma off with no flag). A deck target's own row carries the flag; a reference target's
    goes on every row (it sets the frame).
    """
    def left(label: str, ks: Sequence[int]) -> set:
        return {t for k in ks for t in model.visit(visit_label(label, k)).left_out}

    sides = [(left(lab, setups), "")] + ([(left(baseline, base_setups), baseline)] if baseline != lab else [])
    if not any(out for out, _ in sides):
        return result

    def flag(target: str, where: str) -> str:
        what = "reference target" if groups.get(target) == "reference" else "target"
        text = f"{FLAG_FIELD_MISFIT}: {what} {target} did not fit the field model and was left out of its fit"
        return in_baseline(text, where) if where else text

    rows = []
    for d in result.displacements:
        if np.isfinite(d.displacement_m):
            extra = [flag(t, where) for out, where in sides for t in sorted(out)
                     if t == d.reflector or groups.get(t) == "reference"]
            extra = [f for f in extra if f not in d.flags]
            if extra:
                d = replace(d, flags=tuple(d.flags) + tuple(extra))
        rows.append(d)
    return replace(result, displacements=tuple(rows))


def _with_centroid_doubts(visit: VisitInputs, base: VisitInputs, result: EpochDisplacements) -> EpochDisplacements:
    """A displacement whose centroid (in the visit or the baseline) carries a warning carries it on its row too.

    A surveyor reads the displacement table, not the centroids: a target measured at grazing incidence, beside
    a second bright object or off its expected position says so where its number is (the baseline's with
    ``(in the baseline L)`` after it). Every set-up's found centroids count.
    """
    def said(flag: str, where: str) -> str:
        return in_baseline(flag, base.label) if where else flag

    def found_flags(v: VisitInputs) -> dict:  # the sightings the displacement used (not a weak one left out of a join)
        out: dict = {}
        found = {k: v.found_setup(k) for k in v.setups}
        for cents in without_weak_duplicates(found).values():
            for t, c in cents.items():
                out.setdefault(t, []).extend(f for f in c.flags if f not in out.get(t, []))
        return out

    sides = [(found_flags(visit), "")] + ([(found_flags(base), "b")] if base.label != visit.label else [])
    rows = []
    for d in result.displacements:
        if np.isfinite(d.displacement_m):
            extra = [said(f, where) for flags, where in sides for f in flags.get(d.reflector, ())
                     if severity(f) in (WARNING, PROBLEM) and said(f, where) not in d.flags]
            if extra:
                d = replace(d, flags=tuple(d.flags) + tuple(extra))
        rows.append(d)
    return replace(result, displacements=tuple(rows))


def why_missing(visit: VisitInputs, result: EpochDisplacements) -> EpochDisplacements:
    """A target without a value says why on its row, in one flag: one fact, one name.

    An occluded target's centroid carries ``not_found`` and its reason (``no_compact_target``); its row carries
    ``missing`` with that reason in its text (``missing: no disc-shaped target``). A target no set-up of the
    visit could resolve (the disc narrower than the beam from every station) is not missing but ``unresolved``,
    which is advice for the next visit's station (information), not a surveyor's action now.
    """
    if not any(has(d.flags, FLAG_MISSING) for d in result.displacements):
        return result
    every = [visit.centroids.get(k, {}) for k in visit.setups]
    rows = []
    for d in result.displacements:
        seen = [cents[d.reflector] for cents in every if d.reflector in cents]
        if has(d.flags, FLAG_MISSING) and seen and not any(t.found for t in seen):
            unresolved = [f for t in seen for f in t.flags if code(f) == FLAG_UNRESOLVED]
            reasons = [f for t in seen for f in t.flags if code(f) not in (FLAG_NOT_FOUND, FLAG_UNRESOLVED)]
            others = tuple(f for f in d.flags if code(f) != FLAG_MISSING)
            if unresolved and len(unresolved) == len(seen):
                d = replace(d, flags=(unresolved[0],) + others)
            elif reasons:
                said = "; ".join(dict.fromkeys(words(f) for f in reasons))
                d = replace(d, flags=(f"{FLAG_MISSING}: {said}",) + others)
        rows.append(d)
    return replace(result, displacements=tuple(rows))


def _failed_result(groups: Mapping[str, str], base: Mapping, cents: Mapping, baseline: str, reason: str, *,
                   flag: str | None = None) -> EpochDisplacements:
    """A visit with no displacement: every deck target missing, and a problem flag saying why (or ``flag``)."""
    refs = [r for r, g in groups.items() if g == "reference"]
    meas = [m for m, g in groups.items() if g == "measurement"]
    both = [r for r in refs if r in base and r in cents]
    found_meas = [m for m in meas if m in cents]
    if flag is not None:
        pass
    elif not both:
        flag = (f"{FLAG_PIERS_NOT_MEASURED}: no reference target was found in both this epoch and the baseline "
                f"{baseline} ({len([r for r in refs if r in cents])} of {len(refs)} found here)")
    elif len(found_meas) < 3:
        flag = f"{FLAG_DECK_NOT_MEASURED}: {len(found_meas)} of {len(meas)} deck targets found, at least 3 needed"
    else:
        flag = f"{FLAG_NO_DISPLACEMENT}: {reason}"
    nan = float("nan")
    disp = tuple(Displacement(m, nan, nan, nan, nan, (FLAG_MISSING,)) for m in meas)
    return EpochDisplacements(disp, (), (), np.full(3, nan), np.full(3, nan), "none", (flag,))


def _chain(inputs: Stage2Inputs, history: Mapping[str, list[StoredDisplacement]], d: Displacement,
           base_label: str) -> Displacement:
    """A target first measured after the baseline: continue the history of the target it replaced."""
    old = inputs.replaces.get(d.reflector)
    if not old:
        return d
    at = inputs.order.get(base_label)
    rows = [r for r in history.get(old, []) if at is None or r.order <= at]
    if not rows or not np.isfinite(d.displacement_m):
        return d
    last = max(rows, key=lambda r: r.order)
    return replace(d, displacement_m=d.displacement_m + last.displacement_m,
                   sigma_m=float(np.hypot(d.sigma_m, last.sigma_m)), flags=tuple(d.flags) + (FLAG_CHAINED,))


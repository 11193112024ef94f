"""The state of a campaign at a glance: every epoch's stage and every target's latest displacement.

One home for an epoch's state: :func:`decide_state` turns a stage and *all* the epoch's flags (its own,
its targets' displacement flags and its centroid flags, reference targets included) into the state that
``bridgesurvey status``, the displacements CSV (``epoch_state``), the desktop application's campaign tree
and the report show. :func:`epoch_states` gives it for every epoch of a campaign at once,
:func:`epoch_state` for one.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from common.flags import (
    FLAG_DEPARTS,
    FLAG_NOT_FOUND,
    FLAG_REFERENCE_AMBIGUOUS,
    FLAG_UNRESOLVED,
    PROBLEM,
    WARNING,
    code,
    has,
    is_from_baseline,
    words,
    worst,
)
from projects.series.predictions import predictions
from projects.store.campaign import Campaign
from projects.store.records import DisplacementRecord

#: Epoch stages, in the order work moves them along; the last three are processed epochs by the
#: most serious flag they carry (see :mod:`common.flags`): none or information only, a warning, a problem.
EPOCH_STATES = ("imported", "planned", "scanned", "measured", "processed", "warning", "problem")

#: The stages before displacements exist; :func:`decide_state` passes them through unchanged.
STAGES = ("imported", "planned", "scanned", "measured", "processed")


@dataclass(frozen=True)
class EpochState:
    """An epoch's state and every flag it carries.

    Attributes
    ----------
    epoch : str
        The epoch's label.
    state : str
        One of :data:`EPOCH_STATES`.
    flags : tuple of str
        The epoch's own flags first, then its targets' flags, each with the targets that carry it
        (``second_bright_object: R1``, ``missing: M2 M4``).
    """

    epoch: str
    state: str
    flags: tuple[str, ...]

    @property
    def severity(self) -> str | None:
        """The most serious severity among the flags (None without flags)."""
        return worst(self.flags)


def decide_state(stage: str, flags: Iterable[str]) -> str:
    """The state of an epoch at ``stage`` carrying ``flags``.

    Before its displacements exist an epoch is at its stage (imported, planned, scanned, measured);
    once processed, its most serious flag decides: a problem, a warning, or processed (information
    flags only, or none). Every flag counts, a reference target's centroid flag as much as the epoch's.

    >>> decide_state("processed", ["normal_refitted_in_epoch"])
    'processed'
    >>> decide_state("processed", ["second_bright_object: R1"])
    'warning'
    >>> decide_state("processed", ["missing: M2", "deck_not_measured"])
    'problem'
    >>> decide_state("measured", ["second_bright_object: R1"])
    'measured'
    """
    if stage not in STAGES:
        raise ValueError(f"unknown epoch stage {stage!r}")
    if stage != "processed":
        return stage
    level = worst(flags)
    return level if level in (WARNING, PROBLEM) else "processed"


def target_flags(per_target: Mapping[str, Sequence[str]]) -> list[str]:
    """Per-target flags as one entry per flag, naming the targets that carry it (targets sorted).

    >>> target_flags({"R1": ["second_bright_object"], "M2": ["missing"], "M4": ["missing"]})
    ['missing: M2 M4', 'second_bright_object: R1']
    """
    owners: dict[str, list[str]] = {}
    for rid in sorted(per_target):
        for f in per_target[rid]:
            owners.setdefault(f, [])
            if rid not in owners[f]:
                owners[f].append(rid)
    return [f"{f}: {' '.join(ids)}" if f == code(f) else f"{f} ({' '.join(ids)})" for f, ids in sorted(owners.items())]


@dataclass(frozen=True)
class Departure:
    """A target's design prediction at an epoch and how far the measurement departs from it (mm, positive up).

    ``departs`` is True when the departure exceeds the target's tolerance (``limit --rule prediction:TOL``):
    the row then carries :data:`common.flags.FLAG_DEPARTS`.
    """

    predicted_mm: float
    departure_mm: float | None
    departs: bool


def departures(c: Campaign, records: Sequence[DisplacementRecord] | None = None
               ) -> dict[tuple[str, str], Departure]:
    """``(epoch, reflector) -> Departure`` for every displacement (default: all stored) inside its prediction."""
    preds = predictions(c)
    if not preds:
        return {}

    when = {e.label: e.when for e in c.epochs()}
    tols = c.settings().get("prediction_tolerance_mm") or {}
    out = {}
    for r in c.displacements() if records is None else records:
        p = preds.get(r.reflector)
        t_ns = int(when[r.epoch].timestamp() * 1e9)
        if p is None or not p[0][0] <= t_ns <= p[0][-1]:
            continue
        pred = float(np.interp(t_ns, p[0], p[1]))
        dep = None if r.displacement_m is None else r.displacement_m * 1000.0 - pred
        tol = tols.get(r.reflector, tols.get("*"))
        out[(r.epoch, r.reflector)] = Departure(pred, dep, dep is not None and tol is not None and abs(dep) > tol)
    return out


def _own_flags(c: Campaign, label: str, flags: Sequence[str]) -> list[str]:
    """The epoch's own flags, an ambiguous reference change naming its suspects."""
    out = list(flags)
    if FLAG_REFERENCE_AMBIGUOUS in out:
        suspects = [r.reflector for r in c.reference_checks(label) if r.suspect]
        if suspects:
            out[out.index(FLAG_REFERENCE_AMBIGUOUS)] = \
                f"{FLAG_REFERENCE_AMBIGUOUS}: {' or '.join(suspects)} moved (both left out)"
    return out


def _one_name(flags: Sequence[str]) -> list[str]:
    """A centroid's flags with a target not found said once: ``not_found`` with its reason in plain words."""
    if not has(flags, FLAG_NOT_FOUND):
        return list(flags)
    reasons = [f for f in flags if code(f) != FLAG_NOT_FOUND]
    if any(code(f) == FLAG_UNRESOLVED for f in reasons):
        return [f for f in reasons if code(f) == FLAG_UNRESOLVED][:1]
    if not reasons:
        return [FLAG_NOT_FOUND]
    return [f"{FLAG_NOT_FOUND}: " + "; ".join(dict.fromkeys(words(f) for f in reasons))]


def _stage(c: Campaign, label: str, has_displacements: bool) -> str:
    if has_displacements:
        return "processed"
    res = c.result(label)
    if res is None:
        return "imported"
    if res.stage == "planned":
        return "scanned" if c.files(label, "fine") else "planned"
    return "measured"


def epoch_states(c: Campaign, labels: Sequence[str] | None = None, *,
                 departed: Mapping[tuple[str, str], Departure] | None = None) -> dict[str, EpochState]:
    """The :class:`EpochState` of every epoch (or of ``labels``), in date order.

    Flags: the epoch's own (from its displacement computation), then every target's displacement flags
    (a departure from the design prediction included) and centroid flags, with the targets named.
    ``departed`` is :func:`departures` when the caller has it already.
    """
    wanted = [e.label for e in c.epochs()] if labels is None else list(labels)
    per_target: dict[str, dict[str, list[str]]] = {lab: {} for lab in wanted}
    records = c.displacements()
    departed = departures(c, records) if departed is None else departed
    with_rows = {(r.epoch, r.reflector) for r in records}
    for r in records:
        if r.epoch in per_target:
            extra = [FLAG_DEPARTS] if (d := departed.get((r.epoch, r.reflector))) is not None and d.departs else []
            own = [f for f in r.flags if not is_from_baseline(f)]  # the baseline's doubts are in its own state
            if own or extra:
                per_target[r.epoch].setdefault(r.reflector, []).extend(own + extra)
    out = {}
    for lab in wanted:
        ds = c.displacement_set(lab)
        targets = per_target[lab]
        sightings: dict[str, list[tuple[str, ...]]] = {}  # each set-up's centroid flags (found unless not_found)
        for k in c.setups(lab):  # every set-up's: a target one could not see and another measured is measured
            for rid, cflags in c.centroid_flags(lab, k).items():
                sightings.setdefault(rid, []).append(cflags)
        for rid, seen in sightings.items():
            found = [fl for fl in seen if FLAG_NOT_FOUND not in fl]
            if found or (lab, rid) in with_rows:  # its row says a missing target's reason ('missing' flag)
                for fl in found:
                    targets.setdefault(rid, []).extend(f for f in fl if f not in targets.get(rid, ()))
                continue
            for fl in seen:
                targets.setdefault(rid, []).extend(f for f in _one_name(fl) if f not in targets[rid])
        flags = (_own_flags(c, lab, ds.flags) if ds is not None else []) + target_flags(targets)
        out[lab] = EpochState(lab, decide_state(_stage(c, lab, ds is not None), flags), tuple(flags))
    return out


def epoch_flags(c: Campaign, label: str) -> list[str]:
    """Every flag of one epoch: its own, then its targets' (displacement and centroid) with the targets named."""
    return list(epoch_states(c, [label])[label].flags)


def epoch_state(c: Campaign, label: str) -> tuple[str, list[str]]:
    """(state, flags) of one epoch (see :func:`decide_state` and :func:`epoch_states`)."""
    c.epoch(label)
    s = epoch_states(c, [label])[label]
    return s.state, list(s.flags)

"""A pier that moved along the span, told from a scale the air does not explain.

A visit's similarity fit reads one pier sliding along the span against the others as a range scale: 3 mm over
a 38 m span is 79 ppm. Taken as the atmosphere's, that scale would stretch every vector between the piers and
the deck, a few tenths of a millimetre of height each. With an air series, such a scale is a reference-group
question (the air cannot explain it, and an instrument that corrects for the air would leave none).

So for every visit whose scale agrees neither with the air nor with none
(:func:`lidar.systematic.atmosphere.air_agreement`), each pier in turn is supposed moved: the field model is fitted
again with that pier's targets given one shift of their own along the span in that visit and the visit's scale
held to the air's prediction (its sigma :data:`~lidar.systematic.atmosphere.AIR_SCALE_SIGMA_PPM`). An explanation
counts when the visit's centroids then fit as their sigmas say (misfit under :data:`MISFIT_LIMIT`) and the shift
stands out of its sigma; the best one is kept (its targets are moved back by the shift before the displacements
are computed, :mod:`lidar.systematic.corrections`). When another pier explains the visit about as well (two piers
only: one sliding forward reads as the other sliding back), both are named.

The piers are the reference targets grouped by their position along the span in the baseline (the deck targets'
long axis): targets closer than :data:`PIER_GAP_M` along it are on one pier.
"""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from lidar.systematic.adjustment import FieldModel, VisitSightings, fit_field_model
from lidar.systematic.atmosphere import AIR_SCALE_SIGMA_PPM, air_agreement

#: Reference targets closer than this along the span are on one pier (metres; a pier is 1-3 m long, a span 10+).
PIER_GAP_M = 4.0
#: An explanation's visit must fit its centroids' sigmas to this (RMS normalised residual).
MISFIT_LIMIT = 2.0
#: Another pier explains the visit about as well when its chi-square is within this factor of the best one's.
DECISIVE_RATIO = 4.0
#: The shift must stand out of its own sigma by this much.
SHIFT_SIGMAS = 3.0


def piers(baseline: VisitSightings, groups: Mapping[str, str]) -> tuple[np.ndarray, list[tuple[str, ...]]] | None:
    """The span's axis (unit, the baseline's frame) and the reference targets on each pier, in order along it.

    From the baseline's sightings: the axis is the deck targets' long axis (at least three needed), the piers
    are the reference targets grouped where they lie along it. The axis points away from the pier of the first
    reference target in natural order (R1's). None without two piers.
    """
    deck = np.array([s.xyz_socs for s in baseline.sightings if groups.get(s.target) == "measurement"])
    refs: dict[str, np.ndarray] = {}
    for s in baseline.sightings:
        if groups.get(s.target) == "reference":
            refs.setdefault(s.target, np.asarray(s.xyz_socs, dtype=np.float64))
    if len(deck) < 3 or len(refs) < 2:
        return None
    c = deck - deck.mean(axis=0)
    axis = np.linalg.eigh(c.T @ c)[1][:, -1]
    first = min(refs, key=_natural)  # positive away from the pier of the first reference target (R1's)
    if float((refs[first] - deck.mean(axis=0)) @ axis) > 0:
        axis = -axis
    along = {r: float(x @ axis) for r, x in refs.items()}
    order = sorted(along, key=lambda r: (along[r], r))
    out: list[list[str]] = [[order[0]]]
    for a, b in zip(order[:-1], order[1:], strict=False):
        if along[b] - along[a] > PIER_GAP_M:
            out.append([])
        out[-1].append(b)
    if len(out) < 2:
        return None
    return axis, [tuple(sorted(p)) for p in out]


def _natural(name: str) -> tuple:
    """A sort key that puts R2 before R10."""
    return tuple((0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", name) if t)


def _prior_centre(model: FieldModel, predicted: Mapping[str, float], suspects: set[str]) -> float:
    """How much of the air's prediction a suspect visit's scale is held to (1, or 0).

    0 when most other visits say that the instrument corrected for the air itself (their scales near none).
    """
    corrected = uncorrected = 0
    for lab, ppm in predicted.items():
        v = model.visits.get(lab)
        if lab in suspects or v is None or not v.scale_determined or lab == model.baseline:
            continue
        agrees, none = air_agreement(v.scale_ppm, v.scale_sigma_ppm, ppm)
        corrected += none and not agrees
        uncorrected += agrees and not none
    return 0.0 if corrected > uncorrected else 1.0


def explain_scales(model: FieldModel, visits: Sequence[VisitSightings], groups: Mapping[str, str],
                   predicted: Mapping[str, float]) -> tuple[FieldModel, list[VisitSightings]]:
    """The field model with every scale the air does not explain put down to a pier that moved, where one does.

    Parameters
    ----------
    model : FieldModel
        The campaign's model fitted on ``visits`` as they are.
    visits : sequence of VisitSightings
        The baseline's first (as fitted).
    groups : mapping target id -> "reference" | "measurement"
    predicted : mapping visit label -> ppm
        The scale the air predicts for each visit against the baseline (visits without air left out).

    Returns
    -------
    (model, visits) : the model fitted again with the explanations kept (``model`` itself when none is), and the
    visits with their hypotheses (:attr:`VisitSightings.shifted`).
    """
    visits = list(visits)
    suspects = []
    for lab, ppm in predicted.items():
        v = model.visits.get(lab)
        if v is None or lab == model.baseline or not v.scale_determined:
            continue
        agrees, none = air_agreement(v.scale_ppm, v.scale_sigma_ppm, ppm)
        if not agrees and not none:
            suspects.append(lab)
    layout = piers(visits[0], groups) if suspects else None
    if layout is None:
        return model, visits
    axis, groups_of_piers = layout
    weight = _prior_centre(model, predicted, set(suspects))
    index = {v.label: k for k, v in enumerate(visits)}
    kept = False
    for lab in suspects:
        k = index.get(lab)
        if k is None:
            continue
        seen = {s.target for s in visits[k].sightings}
        present = [p for p in groups_of_piers if seen.intersection(p)]
        if len(present) < 2:
            continue
        prior = (weight * predicted[lab], AIR_SCALE_SIGMA_PPM)
        fits = []
        for pier in present:
            trial = list(visits)
            trial[k] = replace(visits[k], shifted=tuple(t for t in pier if t in seen), shift_axis=axis,
                               scale_prior_ppm=prior)
            m = fit_field_model(trial, groups, basis=model.range_walk.basis)
            v = m.visit(lab)
            fits.append((v.misfit ** 2, pier, v, trial[k]))
        fits.sort(key=lambda f: f[0])
        chi2, pier, v, hypothesis = fits[0]
        if v.misfit > MISFIT_LIMIT or abs(v.shift_m) < SHIFT_SIGMAS * v.shift_sigma_m:
            continue
        others = tuple(t for f in fits[1:] if f[0] < DECISIVE_RATIO * max(chi2, 1.0) for t in f[1] if t in seen)
        visits[k] = replace(hypothesis, shift_alternatives=others)
        kept = True
    if not kept:
        return model, visits
    return fit_field_model(visits, groups), visits

"""The campaign's field model over its visits: fitted over every measured visit, kept while it holds.

Stage 2 (:mod:`lidar.stage2`) corrects every visit's centroids for the atmosphere's scale, the retro-reflector
range walk and the set-up's drift (:mod:`lidar.systematic`) before computing its displacements. The model is
fitted over every measured visit at once; when visits arrive, it is fitted again, and the stored model is
replaced only when the new one differs materially (a range walk changing by more than :data:`MATERIAL_BIAS_M`
anywhere the campaign measured, a visit's scale by more than :data:`MATERIAL_SCALE_PPM`, its drift by more
than :data:`MATERIAL_DRIFT_ARCSEC_H`, the instrument's axis errors come or go or move by more than
:data:`MATERIAL_AXES_ARCSEC`); otherwise the new visits' own terms are added to it. So adding a visit
recomputes that visit's displacements, and all of them only when the campaign's knowledge of its instrument
has changed.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace

import numpy as np

from common.flags import (
    FLAG_ATMOSPHERE_CORRECTED,
    FLAG_ATMOSPHERE_DISAGREES,
    FLAG_ATMOSPHERE_UNCORRECTED,
    FLAG_DRIFT_FROM_PLAN,
    FLAG_PIER_MOVED,
    FLAG_RANGE_WALK_UNDETERMINED,
    FLAG_SCALE_UNDETERMINED,
    FLAG_TRANSIENTS_UNCHECKED,
)
from lidar.centroid import TargetCentroid, is_weak
from lidar.systematic.adjustment import FieldModel, Sighting, VisitSightings, VisitSystematics, fit_field_model
from lidar.systematic.atmosphere import air_agreement, range_scale_ppm
from lidar.systematic.corrections import cos_incidence_of
from lidar.systematic.pier_slide import explain_scales
from lidar.systematic.range_walk import RangeWalkModel

MATERIAL_BIAS_M = 1e-5
MATERIAL_SCALE_PPM = 0.3
MATERIAL_DRIFT_ARCSEC_H = 0.5
MATERIAL_AXES_ARCSEC = 0.5


def sightings(cents: Mapping[str, TargetCentroid], closures: Mapping[str, TargetCentroid] | None = None) -> tuple:
    """The found centroids (and closure centroids) of one epoch as the field model's sightings.

    A weak centroid (:func:`lidar.centroid.is_weak`: a disc narrower than the beam, its centroid millimetres off
    along the line of sight) is left out: at the far end of the incidences it would steer the range walk's
    curve, which the well-resolved discs of every visit are corrected by.
    """
    out = []
    for c in list(cents.values()) + list((closures or {}).values()):
        if not c.found or is_weak(c.flags):
            continue
        out.append(Sighting(c.reflector, np.asarray(c.xyz_socs, dtype=np.float64), np.asarray(c.cov, dtype=np.float64),
                            cos_incidence_of(c), float(c.time_s)))
    return tuple(out)


Air = tuple[float, float, float]  # temperature degC, pressure hPa, relative humidity 0..1


def identity_model(baseline: str) -> FieldModel:
    """A field model that corrects nothing (the campaign cannot be modelled yet)."""
    return FieldModel(baseline, RangeWalkModel(), {})


def usable(cents: Mapping[str, TargetCentroid], groups: Mapping[str, str]) -> bool:
    """Whether a visit found the three reference targets that place it in the adjustment."""
    return sum(1 for k, c in cents.items() if c.found and groups.get(k) == "reference") >= 3


def _material(new: FieldModel, old: FieldModel, visits: Sequence[VisitSightings]) -> bool:
    if new.baseline != old.baseline or bool(new.range_walk.basis) != bool(old.range_walk.basis):
        return True
    if new.axes.fitted != old.axes.fitted or (new.axes.fitted and np.max(np.abs(
            new.axes.values_arcsec - old.axes.values_arcsec)) > MATERIAL_AXES_ARCSEC):
        return True
    r = np.array([np.linalg.norm(s.xyz_socs) for v in visits for s in v.sightings])
    c = np.array([s.cos_incidence for v in visits for s in v.sightings])
    if r.size and np.max(np.abs(new.range_walk.bias_m(r, c) - old.range_walk.bias_m(r, c))) > MATERIAL_BIAS_M:
        return True
    for label, v_old in old.visits.items():
        v_new = new.visits.get(label)
        if v_new is None:
            continue
        if v_new.shifted != v_old.shifted or abs(v_new.shift_m - v_old.shift_m) > MATERIAL_BIAS_M:
            return True
        if abs(v_new.scale_ppm - v_old.scale_ppm) > MATERIAL_SCALE_PPM or \
                np.max(np.abs(v_new.drift_arcsec_h - v_old.drift_arcsec_h)) > MATERIAL_DRIFT_ARCSEC_H:
            return True
    return False


def _merged(old: FieldModel, new: FieldModel) -> FieldModel:
    """The stored model with the new fit's terms for the visits it did not have."""
    visits = dict(old.visits)
    for label, v in new.visits.items():  # its scales under the new fit's alternatives do not apply to the old ones
        visits.setdefault(label, replace(v, alternative_scale_ppm=()))
    return FieldModel(old.baseline, old.range_walk, visits, old.sigma0, new.n_observations, old.notes, old.axes)


def visit_digest(model: FieldModel, baseline: str, label: str) -> str:
    """A digest of what one epoch's displacements depend on: the range walk and both visits' terms."""
    part = {"rw": model.range_walk.to_json(), "base": _visit_key(model.visit(baseline)),
            "epoch": _visit_key(model.visit(label))}
    if model.axes.fitted:  # (a model without them keeps the digests it had)
        part["axes"] = np.round(model.axes.values_arcsec, 4).tolist()
    return hashlib.sha256(json.dumps(part, sort_keys=True).encode()).hexdigest()[:24]


def _visit_key(v: VisitSystematics) -> dict:
    out = {"scale": round(v.scale_ppm, 4), "scale_sigma": round(v.scale_sigma_ppm, 4),
           "drift": np.round(v.drift_arcsec_h, 4).tolist(), "drift_cov": np.round(v.drift_cov, 4).tolist(),
           "t": round(v.time_ref_s, 3), "timed": v.timed}
    if v.shifted:  # only then: the digests of every other visit stay as they were
        out["shift"] = [list(v.shifted), round(v.shift_m * 1e6, 1), round(v.shift_sigma_m * 1e6, 1)]
    return out


def refit(stored: FieldModel | None, baseline: str, labels: Sequence[str], groups: Mapping[str, str],
          found: Callable[[str], Mapping[str, TargetCentroid]],
          closures: Callable[[str], Mapping[str, TargetCentroid]], *, enabled: bool = True,
          air_scale: Mapping[str, float] | None = None) -> FieldModel:
    """Fit the campaign's field model over ``labels`` (the baseline's first) and keep ``stored`` while it holds.

    Visits with fewer than three reference targets found cannot be placed and are left out; a baseline
    without three, or ``enabled=False``, gives a model that corrects nothing. ``labels`` are the model's
    visits (epochs, or the set-ups of epochs: ``L#2``); ``found(label)`` gives a visit's found centroids and
    ``closures(label)`` its closure centroids. The returned model is ``stored`` with the new visits' terms
    added when the new fit does not differ from it materially, else the new fit. ``air_scale`` holds the scale
    the air predicts for each visit against the baseline (ppm; visits without air left out): a scale it does not
    explain is put down to a pier that moved along the span where one does (:mod:`lidar.systematic.pier_slide`).
    """
    if not enabled or not usable(found(baseline), groups):
        return identity_model(baseline)
    order = [baseline] + [lab for lab in labels if lab != baseline and usable(found(lab), groups)]
    visits = [VisitSightings(lab, sightings(found(lab), {k: v for k, v in closures(lab).items()
                                                          if k in found(lab)})) for lab in order]
    new = fit_field_model(visits, groups)
    if air_scale:
        new, visits = explain_scales(new, visits, groups, air_scale)
    if stored is not None and not _material(new, stored, visits):
        return _merged(stored, new)
    return new


def systematics_json(model: FieldModel, label: str, time_source: str | None) -> dict:
    """What an epoch's displacements were corrected for, as stored beside them (and in the CSV)."""
    v = model.visit(label)
    return {"scale_ppm": float(v.scale_ppm), "scale_sigma_ppm": float(v.scale_sigma_ppm),
            "scale_determined": bool(v.scale_determined), "drift_arcsec_h": np.asarray(v.drift_arcsec_h).tolist(),
            "drift_sigma_arcsec_h": v.drift_sigma_arcsec_h.tolist(), "timed": bool(v.timed),
            "time_source": time_source or "none", "range_walk": list(model.range_walk.basis),
            "left_out": list(v.left_out)}


#: Environment readings within this of a visit's time describe its air (seconds).
AIR_WINDOW_S = 3600.0


def air_near(series: Sequence[tuple[str, np.ndarray, np.ndarray]], t_ns: int) -> Air | None:
    """(temperature degC, pressure hPa, relative humidity 0..1) around a time, or None without a temperature.

    ``series`` holds (kind, times ns (N,), values (N,)) of the campaign's environment series; the readings
    within :data:`AIR_WINDOW_S` of ``t_ns`` are averaged per kind; pressure defaults to 1013.25 hPa and
    humidity to 60 % when none was recorded.
    """
    def mean(kind: str) -> float | None:
        vals = [v[(np.abs(t - t_ns) <= AIR_WINDOW_S * 1e9) & np.isfinite(v)] for k, t, v in series if k == kind]
        allv = np.concatenate(vals) if vals else np.zeros(0)
        return float(np.mean(allv)) if allv.size else None

    temp = mean("temperature")
    if temp is None:
        return None
    pres, hum = mean("pressure"), mean("humidity")
    return temp, 1013.25 if pres is None else pres, 0.6 if hum is None else hum / 100.0


def air_scale_ppm(here: Air, base: Air, *, wavelength_nm: float) -> float:
    """The range scale (ppm) the air around a visit predicts against the baseline's air."""
    return range_scale_ppm(*here[:2], relative_humidity=here[2], wavelength_nm=wavelength_nm) - \
        range_scale_ppm(*base[:2], relative_humidity=base[2], wavelength_nm=wavelength_nm)


def atmosphere_flags(model: FieldModel, label: str, here: Air | None, base: Air | None, *,
                     wavelength_nm: float) -> list[str]:
    """What the air's temperature (and pressure) around a visit and the baseline say of its estimated scale.

    The scale the atmosphere predicts against the baseline (group refractivity for the scanner's
    wavelength, :mod:`lidar.systematic.atmosphere`) is compared with the estimate: agreeing, the instrument
    did not correct for the air (the correction is made here); an estimate near zero where the air
    predicts a scale, it did; neither, a warning naming both numbers.
    """
    v = model.visit(label)
    if label == model.baseline or label not in model.visits or not v.scale_determined:
        return []
    if here is None or base is None:
        return []
    predicted = air_scale_ppm(here, base, wavelength_nm=wavelength_nm)
    s = max(v.scale_sigma_ppm, 1e-6)
    if v.shifted:
        against = ", ".join(v.shift_alternatives) if v.shift_alternatives else "the other pier targets"
        either = " (or those against these: the targets cannot tell which pier)" if v.shift_alternatives else ""
        return [f"{FLAG_PIER_MOVED}: {', '.join(v.shifted)} moved {v.shift_m * 1e3:+.1f} +- "
                f"{v.shift_sigma_m * 1e3:.1f} mm along the span against {against}{either}; scale from the air "
                f"{v.scale_ppm:+.1f} +- {s:.1f} ppm (predicted {predicted:+.1f})"]
    agrees, corrected = air_agreement(v.scale_ppm, s, predicted)
    if agrees and not corrected:
        return [f"{FLAG_ATMOSPHERE_UNCORRECTED}: measured {v.scale_ppm:+.1f} +- {s:.1f} ppm, the air predicts "
                f"{predicted:+.1f} ppm"]
    if corrected and not agrees:
        return [f"{FLAG_ATMOSPHERE_CORRECTED}: measured {v.scale_ppm:+.1f} +- {s:.1f} ppm where the air predicts "
                f"{predicted:+.1f} ppm"]
    if not agrees:
        return [f"{FLAG_ATMOSPHERE_DISAGREES}: measured {v.scale_ppm:+.1f} +- {s:.1f} ppm, the air predicts "
                f"{predicted:+.1f} ppm"]
    return []


def epoch_flags(model: FieldModel, label: str, time_source: str | None) -> list[str]:
    """The epoch flags the field model adds: what it could not determine, and how times were had."""
    v = model.visit(label)
    out = []
    if label != model.baseline and label in model.visits and not v.scale_determined:
        out.append(f"{FLAG_SCALE_UNDETERMINED}: sigma {v.scale_sigma_ppm:.0f} ppm")
    if model.range_walk.basis and not model.range_walk.determined:
        out.append(FLAG_RANGE_WALK_UNDETERMINED)
    if time_source == "plan" and v.timed:
        out.append(FLAG_DRIFT_FROM_PLAN)
    if time_source != "points":
        out.append(FLAG_TRANSIENTS_UNCHECKED)
    return out

"""What an epoch's displacements were corrected for, in a surveyor's words (status, report, application).

The field model (:mod:`lidar.systematic`) gives each visit a range scale (ppm against the baseline's) and a
drift of the set-up (arc seconds per hour of tilt about the scanner's x and y axes and of twist about its
z axis); processing stores them beside the epoch's displacements (``Campaign.systematics``). These
helpers turn that record into one short line and into numbers a table can show.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from lidar.systematic.axes import errors_text
from lidar.systematic.range_walk import describe_basis

#: Where the centroid times of an epoch came from, as the line says it.
TIME_SOURCES = {"points": "times from the points", "plan": "times from the plan", "none": "no times"}


@dataclass(frozen=True)
class EpochCorrections:
    """One epoch's scale and drift with their standard deviations (ppm, arc seconds per hour)."""

    scale_ppm: float
    scale_sigma_ppm: float
    scale_determined: bool
    tilt_arcsec_h: float
    tilt_sigma_arcsec_h: float
    twist_arcsec_h: float
    twist_sigma_arcsec_h: float
    timed: bool
    time_source: str
    range_walk: tuple[str, ...]
    left_out: tuple[str, ...]


def norm_sigma(v: Sequence[float], s: Sequence[float]) -> tuple[float, float]:
    """|v| and its first-order standard deviation from independent component sigmas (the larger sigma at 0)."""
    n = math.sqrt(sum(x * x for x in v))
    if n < 1e-12:
        return 0.0, max(s) if s else 0.0
    return n, math.sqrt(sum((x * e) ** 2 for x, e in zip(v, s, strict=False))) / n


def epoch_corrections(systematics: Mapping) -> EpochCorrections | None:
    """The record ``Campaign.systematics(label)`` returns as numbers (None when the epoch has none)."""
    if not systematics or "scale_ppm" not in systematics:
        return None
    d = [float(x) for x in systematics.get("drift_arcsec_h") or (0.0, 0.0, 0.0)]
    ds = [float(x) for x in systematics.get("drift_sigma_arcsec_h") or (0.0, 0.0, 0.0)]
    tilt, tilt_s = norm_sigma((d[0], d[1]), (ds[0], ds[1]))
    return EpochCorrections(
        float(systematics["scale_ppm"]), float(systematics.get("scale_sigma_ppm", 0.0)),
        bool(systematics.get("scale_determined", True)), tilt, tilt_s, abs(d[2]), ds[2],
        bool(systematics.get("timed", False)), str(systematics.get("time_source", "none")),
        tuple(systematics.get("range_walk") or ()), tuple(systematics.get("left_out") or ()))


def corrections_line(systematics: Mapping, *, baseline: bool = False) -> str:
    """``scale +3.1 ± 0.8 ppm; drift: tilt 12 ± 4″/h, twist 3 ± 2″/h (times from the points)``.

    Empty when the epoch has no record (not processed yet, or ``field_model`` off). ``baseline``: the
    epoch is the campaign's baseline, whose scale is zero by definition.
    """
    e = epoch_corrections(systematics)
    if e is None:
        return ""
    if baseline:
        scale = "scale 0 ppm (the baseline defines it)"
    elif not e.scale_determined:
        scale = f"scale not determined (its prior, 0 ± {e.scale_sigma_ppm:.1f} ppm, is in σ)"
    else:
        scale = f"scale {e.scale_ppm:+.1f} ± {e.scale_sigma_ppm:.1f} ppm"
    if e.timed:
        drift = (f"drift: tilt {e.tilt_arcsec_h:.0f} ± {e.tilt_sigma_arcsec_h:.0f}″/h, twist "
                 f"{e.twist_arcsec_h:.0f} ± {e.twist_sigma_arcsec_h:.0f}″/h ({TIME_SOURCES.get(e.time_source, e.time_source)})")
    elif e.time_source in ("points", "plan"):
        drift = "no drift (the campaign's data do not support one)"
    else:
        drift = "drift not estimated (the epoch has no times)"
    out = f"{scale}; {drift}"
    if e.left_out:
        out += f"; left out of the frame: {', '.join(e.left_out)}"
    return out


def instrument_summary(model) -> dict:
    """The campaign's instrument as its field model found it, for ``status``: range walk and axis errors.

    ``model`` is a :class:`lidar.systematic.adjustment.FieldModel`. Returns ``range_walk`` (the chosen law in
    words, ``none`` without one), ``range_walk_determined``, ``axis_errors`` (one ``{"axis", "arcsec",
    "sigma_arcsec"}`` a fitted error, none where the data support none) and ``sigma0``.
    """
    rw = model.range_walk
    return {"range_walk": describe_basis(rw.basis), "range_walk_determined": bool(rw.determined),
            "axis_errors": [{"axis": name, "arcsec": round(v, 1) + 0.0, "sigma_arcsec": round(s, 1)}
                            for name, v, s in model.axes.errors()],
            "sigma0": round(float(model.sigma0), 2)}


def instrument_line(summary: Mapping) -> str:
    """``range walk: none; axis errors: vertical index +28.0 ± 7.5″`` from :func:`instrument_summary`."""
    axes = errors_text((a["axis"], a["arcsec"], a["sigma_arcsec"]) for a in summary["axis_errors"])
    walk = summary["range_walk"] + ("" if summary["range_walk"] == "none" or summary["range_walk_determined"]
                                    else " (not determined: its prior is in σ)")
    return f"range walk: {walk}; axis errors: {axes or 'none the data support'}"

"""Displacement limits and the alarm state of each target.

Rules, per target or as the campaign default:

* ``abs``: warning and alarm thresholds in millimetres;
* ``span``: fractions of the span, e.g. warning L/1000 (KDS, AASHTO) and alarm L/500 (Eurocode);
* ``kr-rail``: the Korean railway limit for passenger comfort by train speed class and span
  (the dissertation's table of deflection limits for railway bridges); the warning is 80 % of it.

A target is in ``alarm`` when |displacement| reaches the alarm limit, in ``warning`` when it
reaches the warning limit, else ``ok``; ``unknown`` without a value.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.errors import InputError

# Span columns (upper bounds, m) and L/N denominators per speed class (km/h).
KR_RAIL_SPANS = (20, 25, 30, 35, 40, 45, 50, 55, 75, 95, 120)
KR_RAIL_DENOMINATORS = {
    "0-200": (1500, 1500, 1600, 1750, 1900, 2100, 2200, 2350, 2500, 2200, 1900),
    "200-270": (1300, 1400, 1500, 1600, 1700, 1900, 2000, 2100, 2000, 1700, 1400),
    "270-350": (1100, 1200, 1300, 1500, 1500, 1400, 1300, 1200, 1100, 800, 600),
}
WARNING_SHARE = 0.8


@dataclass(frozen=True)
class Limit:
    """Warning and alarm thresholds (mm, on |displacement|) and the rule they came from."""

    warning_mm: float | None
    alarm_mm: float | None
    rule: str

    def state(self, displacement_mm: float) -> str:
        if displacement_mm is None or not np.isfinite(displacement_mm):
            return "unknown"
        a = abs(displacement_mm)
        if self.alarm_mm is not None and a >= self.alarm_mm:
            return "alarm"
        if self.warning_mm is not None and a >= self.warning_mm:
            return "warning"
        return "ok"


def kr_rail_limit_mm(span_m: float, speed_class: str) -> float:
    """Korean railway deflection limit (mm) for a span and a train speed class ('0-200', '200-270', '270-350')."""
    if speed_class not in KR_RAIL_DENOMINATORS:
        raise InputError(f"unknown train speed class {speed_class!r}; use one of {', '.join(KR_RAIL_DENOMINATORS)}")
    if not (span_m and span_m > 0):
        raise InputError("the Korean railway limits need the span length (init --span-m)")
    if span_m > KR_RAIL_SPANS[-1]:
        raise InputError(f"the Korean railway table covers spans up to {KR_RAIL_SPANS[-1]} m, not {span_m} m")
    col = next(k for k, s in enumerate(KR_RAIL_SPANS) if span_m <= s)
    return span_m * 1000.0 / KR_RAIL_DENOMINATORS[speed_class][col]


def parse_rule(rule: str, span_m: float | None) -> Limit:
    """A Limit from its text form: 'abs:W,A' (mm), 'span:NW,NA' (L/NW, L/NA) or 'kr-rail:CLASS'."""
    try:
        kind, _, args = rule.partition(":")
        kind = kind.strip().lower()
        if kind == "abs":
            w, a = (float(v) if v.strip() else None for v in args.split(","))
            lim = Limit(w, a, rule)
        elif kind == "span":
            if not (span_m and span_m > 0):
                raise InputError("span-fraction limits need the span length (init --span-m)")
            nw, na = (float(v) for v in args.split(","))
            lim = Limit(span_m * 1000 / nw, span_m * 1000 / na, rule)
        elif kind == "kr-rail":
            alarm = kr_rail_limit_mm(span_m or 0.0, args.strip())
            lim = Limit(WARNING_SHARE * alarm, alarm, rule)
        else:
            raise ValueError
    except InputError:
        raise
    except ValueError:
        raise InputError(f"limit rule {rule!r} not understood; use abs:WARN_MM,ALARM_MM, span:1000,500 "
                         "or kr-rail:0-200") from None
    for v in (lim.warning_mm, lim.alarm_mm):
        if v is not None and not (np.isfinite(v) and v > 0):
            raise InputError(f"limit rule {rule!r}: thresholds must be positive")
    return lim


def set_limit_rule(c, reflector: str, rule: str) -> str:
    """Set a target's (or, with ``"*"``, every measurement target's) limit from its text form.

    Besides the rules of :func:`parse_rule`, ``prediction:T`` sets the tolerance (mm) within which a
    displacement must follow the design prediction (a larger departure is flagged). Returns a line
    saying what was set.
    """
    if not rule.strip().lower().startswith("prediction:"):
        c.set_limit(reflector, rule)
        lim = c.limit_for(reflector)
        return f"limit for {reflector}: warning {lim.warning_mm:.2f} mm, alarm {lim.alarm_mm:.2f} mm ({lim.rule})"
    try:
        tol = float(rule.split(":", 1)[1])
    except ValueError:
        tol = float("nan")
    if not (tol == tol and 0 < tol < 1e4):
        raise InputError(f"limit rule {rule!r}: the tolerance must be a positive number of millimetres")
    if reflector != "*":
        c.reflector(reflector)
    tols = dict(c.settings().get("prediction_tolerance_mm") or {})
    tols[reflector] = tol
    c.set_setting("prediction_tolerance_mm", tols)
    return (f"a displacement departing from the design prediction by more than {tol:g} mm is flagged for "
            f"{'every target' if reflector == '*' else reflector}")

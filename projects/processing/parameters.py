"""Every processing parameter, declared once: name, default, parser, the stage it makes stale, and its help.

The defaults, the validation of ``settings DIR KEY VALUE``, the stage input hashes and the help of the
command line and the application are all generated from :data:`PARAMETERS`.

Stages:

* ``plan`` - stage 1 (plan the fine scans, measure the centroids): changing it plans and measures every
  epoch again;
* ``displacements`` - stage 2: changing it recomputes the displacements only;
* ``baseline`` - which epoch is the baseline (stage 2 of every epoch);
* ``analysis`` - read by the analysis and the age axes, not by processing.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from common.errors import InputError

STAGES = ("plan", "displacements", "baseline", "analysis")


def _positive_float(text: str) -> float:
    v = float(text)
    if not (math.isfinite(v) and v > 0):
        raise ValueError
    return v


def _count_or_zero(text: str) -> int:
    v = int(text)
    if v < 0:
        raise ValueError
    return v


def _optional_positive(text: str) -> float | None:
    return None if text.strip().lower() in ("none", "auto", "") else _positive_float(text)


def _boolean(text: str) -> bool:
    return {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}[text.strip().lower()]


def _factor(text: str) -> float:
    v = _positive_float(text)
    if v < 1.0:
        raise ValueError
    return v


def _min_points(text: str) -> int:
    v = int(text)
    if v < 10:
        raise ValueError
    return v


def _normal_mode(text: str) -> str:
    if text not in ("auto", "reference", "epoch"):
        raise ValueError
    return text


def _vector(text: str) -> str:
    vec = [float(v) for v in text.split(",")]
    if len(vec) != 3 or not all(math.isfinite(v) for v in vec) or not any(vec):
        raise ValueError
    return ",".join(f"{v:g}" for v in vec)


def _xy_or_none(text: str) -> str | None:
    if text.strip().lower() in ("none", "auto", ""):
        return None
    xy = [float(v) for v in text.split(",")]
    if len(xy) != 2 or not all(math.isfinite(v) for v in xy):
        raise ValueError
    return ",".join(f"{v:g}" for v in xy)


def _text_or_none(text: str) -> str | None:
    return text.strip() or None


@dataclass(frozen=True)
class Parameter:
    """One processing parameter.

    Attributes
    ----------
    name : str
    default : object
        The value a new campaign has.
    parse : callable
        ``parse(text) -> value``; raises ValueError (or KeyError) on a bad value.
    stage : {"plan", "displacements", "baseline", "analysis"}
        What changing it makes stale (see the module notes).
    help : str
        One line for ``settings --help`` and the application's dialog.
    values : str
        What may be given, for the help ("a number > 0", "auto | reference | epoch").
    added_later : bool
        A parameter added after campaigns were processed without it: it enters the input hash (stage 1's or
        stage 2's) only when it differs from its default, so those campaigns are not processed again for nothing.
    """

    name: str
    default: Any
    parse: Callable[[str], Any]
    stage: str
    help: str
    values: str
    added_later: bool = False

    def value_of(self, text: str | None) -> Any:
        """The validated value of ``text`` (an :class:`InputError` naming the parameter when it is not one)."""
        if text is None:
            raise InputError(f"give a value for {self.name} ({self.values})")
        try:
            return self.parse(text)
        except (ValueError, KeyError):
            raise InputError(f"{self.name}: {text!r} is not a valid value ({self.values})") from None


PARAMETERS: tuple[Parameter, ...] = (
    Parameter("min_points", 1000, _min_points, "plan", "points to plan on every target", "a whole number >= 10"),
    Parameter("budget_min", 60.0, _positive_float, "plan",
              "time budget of the fine scans of one set-up, minutes (a visit of one set-up: the visit's; a visit of "
              "several set-ups planned together shares budget_min a set-up unless visit_budget_min is given)",
              "a number > 0"),
    Parameter("map_step_deg", None, _optional_positive, "plan",
              "cell size of the coarse scan's reflectance map, degrees (auto: from the scan)", "auto | a number > 0"),
    Parameter("detection_threshold", None, _optional_positive, "plan",
              "normalised intensity a reflector must exceed in the map (auto: from the map)", "auto | a number > 0"),
    Parameter("identification_tolerance_m", 0.15, _positive_float, "plan",
              "how far (m) a detection may be from the layout's prediction and still be that target", "a number > 0"),
    Parameter("levelled", True, _boolean, "plan",
              "the scanner was levelled: identifications implying a tilt lose", "true | false", added_later=True),
    Parameter("max_tilt_deg", None, _optional_positive, "plan",
              "largest tilt an identification may imply, degrees (auto: the scanner profile's)",
              "auto | a number > 0", added_later=True),
    Parameter("layout_up", "0,0,1", _vector, "plan", "the layout frame's up direction", "x,y,z (not all zero)",
              added_later=True),
    Parameter("station_xy", None, _xy_or_none, "plan",
              "roughly where set-up 1's scanner stands, in the layout's frame (within 5 m): settles which way round "
              "a symmetric bridge is seen (none: such a tie is refused)",
              "none | x,y in metres", added_later=True),
    Parameter("closure", True, _boolean, "plan",
              "end every plan with the first reference target's window again, to measure the set-up's drift",
              "true | false", added_later=True),
    Parameter("plan_together", True, _boolean, "plan",
              "plan a visit's set-ups together: each target from the set-up that measures it best, tie targets "
              "to join them, the visit's budget (visit_budget_min: budget_min a set-up) shared. In the same total "
              "time it measures as well as or better than each set-up alone (the long-bridges bench). A set-up "
              "whose fine scans are imported keeps its plan (frozen) and the set-ups added after it are planned "
              "around it, in the time it left of the visit's. False: each set-up planned as if it were alone, "
              "with budget_min each",
              "true | false", added_later=True),
    Parameter("visit_budget_min", None, _optional_positive, "plan",
              "the whole fine-scan time of a visit of several set-ups planned together, minutes, shared among them "
              "(auto: budget_min a set-up, as much as each would have planned alone; the VZ-1000 spends about 2 "
              "minutes a window turning and starting, so a window costs about the same at 100 points as at 1000). "
              "When it is too short for min_points on every target the plan names the targets and the time that "
              "would do, before the visit", "auto | a number > 0", added_later=True),
    Parameter("reference_points_factor", 1.0, _factor, "plan",
              "the reference targets' windows get this many times min_points, from the time the other targets' "
              "points leave in the budget (as many as the instrument's finest steps give): every displacement of a "
              "visit is referred to them, so their centroids' noise is in every value. The finest steps cap a far "
              "pier target (4 gave the bench's reference targets about 25 % more points, 4 minutes more a visit, "
              "an effect within one campaign's spread)", "a number >= 1", added_later=True),
    Parameter("field_model", True, _boolean, "displacements",
              "correct the atmosphere's scale, the retro-reflector range walk and the set-up's drift, estimated "
              "from the campaign's own targets (false: rigid motion only, as before)", "true | false"),
    Parameter("field_window", 52, _count_or_zero, "displacements",
              "visits the field model is fitted over: the baseline and the newest N; an earlier visit keeps the "
              "values computed while it was among them, so a visit costs the same in year ten as in year one "
              "(0: every visit)", "0 | a whole number > 0", added_later=True),
    Parameter("normal_mode", "auto", _normal_mode, "displacements",
              "deck normal: carried from the baseline, re-fitted each epoch, or both combined (auto)",
              "auto | reference | epoch"),
    Parameter("weighted_references", True, _boolean, "displacements",
              "weight the reference targets by their precision (false: the plain mean)", "true | false"),
    Parameter("moved_tolerance_m", 0.001, _positive_float, "displacements",
              "smallest change of a reference distance taken as movement, m (or 4 sigma, whichever is larger)",
              "a number > 0"),
    Parameter("baseline", None, _text_or_none, "baseline",
              "the epoch every displacement is measured against (default: the first measured)", "an epoch label"),
    Parameter("casting_date", None, _text_or_none, "analysis",
              "date the concrete was cast, for age axes and predictions by age", "an ISO 8601 date"),
)

BY_NAME: dict[str, Parameter] = {p.name: p for p in PARAMETERS}
#: Parameters processing reads (``baseline`` and ``casting_date`` are kept as plain settings).
PROCESSING = tuple(p for p in PARAMETERS if p.stage in ("plan", "displacements"))
DEFAULTS: dict[str, Any] = {p.name: p.default for p in PROCESSING}
STAGE1_KEYS = tuple(p.name for p in PROCESSING if p.stage == "plan")
#: Stage-1 parameters only a visit planned together reads: in its visit hash, not in each set-up's own.
VISIT_KEYS = ("plan_together", "visit_budget_min")
STAGE2_KEYS = tuple(p.name for p in PROCESSING if p.stage == "displacements")
#: Names ``settings`` takes besides the parameters: the scanner and the campaign's time zone
#: (:attr:`projects.store.campaign.Campaign.timezone`), each handled on its own.
OTHER_SETTINGS = ("scanner", "timezone")


def parameter(name: str) -> Parameter:
    """The parameter called ``name`` (an :class:`InputError` listing them all when there is none)."""
    try:
        return BY_NAME[name]
    except KeyError:
        raise InputError(f"unknown setting {name!r}; settings are "
                         f"{', '.join([*BY_NAME, *OTHER_SETTINGS])}") from None


def stage1_params(params: dict) -> dict:
    """The parameters stage 1 depends on (their hash decides whether an epoch is planned and measured again).

    ``plan_together`` and ``visit_budget_min`` (:data:`VISIT_KEYS`) are not among them: a set-up planned together
    has the other set-ups' inputs and the visit's budget in its plan hash (``projects.processing.stages._visit_hash``),
    one alone or of a one-set-up visit is planned the same either way, so changing them re-plans only the visits they
    change (and none whose fine scans are in: frozen).
    """
    return {p.name: params[p.name] for p in PROCESSING
            if p.stage == "plan" and p.name not in VISIT_KEYS and (not p.added_later or params[p.name] != p.default)}


def visit_budget_seconds(params: dict, setups: int) -> float:
    """The fine-scan time of a visit of ``setups`` set-ups planned together, seconds (shared among them).

    ``visit_budget_min`` when given, else ``budget_min`` a set-up: the same total time as the set-ups planned
    alone, each with ``budget_min`` (issue 40: planned together in one set-up's time, every window got too few
    points, and planning together looked worse than alone when it only had half the time).

    Examples
    --------
    >>> visit_budget_seconds({"budget_min": 60.0, "visit_budget_min": None}, 2)
    7200.0
    >>> visit_budget_seconds({"budget_min": 60.0, "visit_budget_min": 90.0}, 2)
    5400.0
    """
    given = params.get("visit_budget_min")
    return float(given) * 60.0 if given is not None else float(params["budget_min"]) * 60.0 * max(int(setups), 1)


def stage2_params(params: dict) -> dict:
    """The parameters stage 2 depends on."""
    return {k: params[k] for k in STAGE2_KEYS if not BY_NAME[k].added_later or params[k] != BY_NAME[k].default}


def help_text() -> str:
    """Every parameter with its values, default and meaning, for ``settings --help``."""
    lines = []
    for p in PARAMETERS:
        default = "none" if p.default is None else str(p.default).lower() if isinstance(p.default, bool) \
            else str(p.default)
        lines.append(f"  {p.name} ({p.values}; default {default}; stale: {p.stage}): {p.help}")
    return "\n".join(lines)

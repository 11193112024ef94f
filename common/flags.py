"""Every flag the product raises, declared once: its code, severity, meaning and the package that raises it.

Flags come from the centroids (a doubt about one target), the displacement computation (the reference
check, the deck normal, the frame), processing (an epoch that gave no result) and the camera
cross-check. They are not equally serious, and treating them alike turns every epoch red (alarm fatigue):

* **info** - how a result was obtained; nothing to do (``normal_refitted_in_epoch``).
* **warning** - a result exists but deserves a look (a target missing, a moved pier target left out, a
  second bright object in a window).
* **problem** - the epoch has no trustworthy result (no deck or pier targets measured, inconsistent
  references): act before the next visit.

A flag may carry its reason after a colon (``deck_not_measured: 0 of 6 deck targets found``); its code is
the part before it. Producers import the constants below; a code that is not registered here is an error
(:class:`UnknownFlagError`), never guessed: stored campaigns from older versions have their codes mapped
by a migration (:data:`RENAMED`).
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from common.errors import SurveyError

INFO, WARNING, PROBLEM = "info", "warning", "problem"
SEVERITIES = (INFO, WARNING, PROBLEM)


class UnknownFlagError(SurveyError):
    """A flag code this version does not know."""


@dataclass(frozen=True)
class Flag:
    """One registered flag.

    Attributes
    ----------
    code : str
        snake_case code, as stored and printed.
    severity : {"info", "warning", "problem"}
    meaning : str
        One line for the report's flag table and the application's details.
    raised_by : str
        The module that raises it.
    """

    code: str
    severity: str
    meaning: str
    raised_by: str


REGISTRY: dict[str, Flag] = {}


def _flag(code: str, severity_: str, meaning: str, raised_by: str) -> str:
    if code in REGISTRY or severity_ not in SEVERITIES or code != code.lower() or "-" in code:
        raise ValueError(f"flag {code!r} declared twice, in another case or with a bad severity")
    REGISTRY[code] = Flag(code, severity_, meaning, raised_by)
    return code


# ---- a target in one fine scan (lidar.centroid)
FLAG_NOT_FOUND = _flag("not_found", WARNING, "target not found in its fine scan (occluded, removed or outside "
                       "the window)", "lidar.centroid")
FLAG_FEW_POINTS = _flag("few_points", WARNING, "fewer points on the target than planned", "lidar.centroid")
FLAG_SECOND_OBJECT = _flag("second_bright_object", WARNING, "a second bright object beside the target was left "
                           "out (cable-tie-like contamination)", "lidar.centroid")
FLAG_CLIPPED = _flag("clipped_by_window", WARNING, "the target touches the edge of its scan window",
                     "lidar.centroid")
FLAG_SATURATED = _flag("saturated", INFO, "intensity saturated on the target", "lidar.centroid")
FLAG_LOW_SEPARABILITY = _flag("low_separability", WARNING, "target and background intensities overlap",
                              "lidar.centroid")
FLAG_SIZE = _flag("size_mismatch", WARNING, "bright area does not match the target diameter", "lidar.centroid")
FLAG_OFF_EXPECTED = _flag("off_expected_position", WARNING, "centroid away from the planned position",
                          "lidar.centroid")
FLAG_LOW_CONTRAST = _flag("no_bright_target", WARNING, "no bright target in the window", "lidar.centroid")
FLAG_NOT_COMPACT = _flag("no_compact_target", WARNING, "bright points but no disc-shaped cluster",
                         "lidar.centroid")
FLAG_GRAZING = _flag("grazing", WARNING, "seen at grazing incidence: the disc is barely wider than the beam, its "
                     "sigma is widened for the bias of a partly resolved disc", "lidar.centroid")
FLAG_UNRESOLVED = _flag("unresolved", WARNING, "not measured: at this range and incidence the disc is narrower "
                        "than the beam (measure it from another station)", "lidar.centroid")

# ---- a target's displacement and the epoch's reference check (lidar.displacement, lidar.pier_moves)
FLAG_MISSING = _flag("missing", WARNING, "no value this epoch (target not found)", "lidar.displacement")
FLAG_MISSING_AT_BASELINE = _flag("missing_at_baseline", INFO, "target not measured in the baseline epoch",
                                 "lidar.displacement")
FLAG_REFERENCE_MOVED = _flag("reference_moved", WARNING, "a reference target moved and was left out of the "
                             "reference group", "lidar.displacement")
FLAG_REFERENCE_MISSING = _flag("reference_missing", WARNING, "a reference target was not found",
                               "lidar.displacement")
FLAG_REFERENCE_INCONSISTENT = _flag("reference_inconsistent", PROBLEM, "reference distances changed beyond "
                                    "tolerance", "lidar.displacement")
FLAG_NORMAL_FROM_EPOCH = _flag("normal_refitted_in_epoch", INFO, "deck normal re-fitted in this epoch (fewer "
                               "references than needed, or the fit agreed with the carried normal)",
                               "lidar.displacement")
FLAG_REFERENCE_AMBIGUOUS = _flag("reference_change_ambiguous", WARNING, "the reference group changed and the "
                                 "moved target could not be singled out", "lidar.displacement")
FLAG_REFERENCE_UNRESOLVED = _flag("reference_move_unresolved", PROBLEM, "a reference target moved and neither the "
                                  "pier targets nor the deck's shape single it out: the displacements rest on the "
                                  "likeliest guess, or on the targets left once both suspects are left out, and may "
                                  "carry that move's tilt (errors of 5-15 sigma seen in simulation)",
                                  "lidar.displacement")
FLAG_REFERENCE_GEOMETRY_WEAK = _flag("reference_geometry_weak", PROBLEM, "the reference targets found (and the "
                                     "deck's sideways stability) cannot fix one of the frame's rotations: all on "
                                     "one line, or in one plane seen edge-on; the displacements are undetermined "
                                     "about that axis", "lidar.displacement")

# ---- the field error budget: scale, range walk, drift (lidar.systematic, projects.processing)
FLAG_SCALE_UNDETERMINED = _flag("scale_undetermined", INFO, "the reference targets cannot determine the "
                                "atmosphere's range scale (too close together): its sigma is a plausible "
                                "atmosphere's", "projects.processing")
FLAG_RANGE_WALK_UNDETERMINED = _flag("range_walk_undetermined", INFO, "too few or too alike stations to determine "
                                     "the retro-reflector range walk: sigma widened to what a plausible bias "
                                     "would cause", "projects.processing")
FLAG_FIELD_MISFIT = _flag("field_model_misfit", WARNING, "the target's centroid did not fit the campaign's field "
                          "model in a visit and was left out of its fit: something the model does not hold (a "
                          "range walk of that target's own, a knock, a cable tie) may bias the value beyond its "
                          "sigma; on every row of an epoch when it is a reference target", "projects.processing")
FLAG_DRIFT_FROM_PLAN = _flag("drift_from_plan_times", INFO, "the fine scans carry no point times: the set-up's "
                             "drift was fitted on the plan's window order and time model", "projects.processing")
FLAG_DRIFT_BEYOND_SPEC = _flag("drift_beyond_tolerance", WARNING, "the set-up turned more during the visit than "
                               "the instrument allows for: re-scan advised", "projects.processing")
FLAG_ATMOSPHERE_UNCORRECTED = _flag("atmosphere_not_corrected_by_instrument", INFO, "the range scale measured on "
                                    "the piers follows the air's temperature and pressure: the instrument did not "
                                    "correct for the atmosphere (the scale is corrected here)", "projects.processing")
FLAG_ATMOSPHERE_CORRECTED = _flag("atmosphere_corrected_by_instrument", INFO, "no range scale left where the air "
                                  "predicts one: the instrument corrected for the atmosphere", "projects.processing")
FLAG_ATMOSPHERE_DISAGREES = _flag("scale_disagrees_with_atmosphere", WARNING, "the range scale measured on the "
                                  "piers disagrees with what the air's temperature and pressure predict",
                                  "projects.processing")

# ---- an epoch with no result, or a history (projects.processing)
FLAG_DECK_NOT_MEASURED = _flag("deck_not_measured", PROBLEM, "too few deck targets measured for a "
                               "displacement", "projects.processing")
FLAG_PIERS_NOT_MEASURED = _flag("piers_not_measured", PROBLEM, "no reference target measured in both this "
                                "epoch and the baseline", "projects.processing")
FLAG_NO_DISPLACEMENT = _flag("no_displacement", PROBLEM, "the displacements could not be computed (the reason "
                             "follows)", "projects.processing")
FLAG_SETUP_NOT_JOINED = _flag("setup_not_joined", PROBLEM, "a set-up of the visit could not be joined to the "
                              "others (too few well-spread shared targets): its targets are left out",
                              "projects.processing.setups")
FLAG_SETUP_JOIN_MISFIT = _flag("setup_join_misfit", WARNING, "a target seen from two set-ups disagreed beyond its "
                               "sigmas and was measured from one of them only", "projects.processing.setups")
FLAG_SETUP_NOT_MEASURED = _flag("setup_not_measured", WARNING, "a set-up of the visit has no fine scans (or they "
                                "failed): the targets only it sees are missing", "projects.processing")
FLAG_CHAINED = _flag("chained_to_replaced_target", INFO, "history continues from a replaced target",
                     "projects.processing")
FLAG_DEPARTS = _flag("departs_from_prediction", WARNING, "the displacement departs from the design prediction "
                     "by more than its tolerance", "projects.results")

# ---- the camera cross-check (vision.crossval)
FLAG_NO_CAMERA_DATA = _flag("no_camera_data", WARNING, "no camera samples around this LiDAR epoch",
                            "vision.crossval")
FLAG_FEW_CAMERA_SAMPLES = _flag("few_camera_samples", INFO, "few camera samples around this LiDAR epoch",
                                "vision.crossval")
FLAG_NO_LIDAR_VALUE = _flag("no_lidar_value", WARNING, "no LiDAR displacement at this epoch", "vision.crossval")

# ---- one frame of the dual-camera method (vision.compensation)
FLAG_MAIN_TARGET_MISSING = _flag("main_target_missing", WARNING, "the main camera's target was not found in "
                                 "this frame", "vision.compensation")
FLAG_SUB_TARGET_MISSING = _flag("sub_target_missing", WARNING, "the sub-camera's checkerboard was not found in "
                                "this frame", "vision.compensation")

#: Codes of older versions and what they are now (applied by the campaign migrations and when reading
#: files written by older versions).
RENAMED: dict[str, str] = {
    "no-camera-data": FLAG_NO_CAMERA_DATA,
    "few-camera-samples": FLAG_FEW_CAMERA_SAMPLES,
    "no-lidar-value": FLAG_NO_LIDAR_VALUE,
    "main-target-missing": FLAG_MAIN_TARGET_MISSING,
    "sub-target-missing": FLAG_SUB_TARGET_MISSING,
}


def code(flag: str) -> str:
    """The flag's code, without its reason.

    >>> code("deck_not_measured: 0 of 6 deck targets found")
    'deck_not_measured'
    """
    return flag.split(":", 1)[0].strip()


def in_baseline(flag: str, baseline: str) -> str:
    """A flag of the baseline's centroid, as repeated on a later epoch's displacement row.

    >>> in_baseline("grazing: the disc is 40 % of the beam's width", "e1")
    "grazing: the disc is 40 % of the beam's width (in the baseline e1)"
    >>> in_baseline("second_bright_object", "e1")
    'second_bright_object: (in the baseline e1)'
    """
    head, _, detail = flag.partition(":")
    return f"{head}: {detail.strip() + ' ' if detail else ''}(in the baseline {baseline})"


def is_from_baseline(flag: str) -> bool:
    """Whether a row's flag is the baseline centroid's, repeated (see :func:`in_baseline`)."""
    return flag.endswith(")") and "(in the baseline " in flag


def has(flags: Iterable[str], flag_code: str) -> bool:
    """Whether ``flags`` hold a flag of code ``flag_code`` (with or without its reason).

    >>> has(["saturated: 40 % at the ceiling"], "saturated"), has(["missing"], "saturated")
    (True, False)
    """
    return any(code(f) == flag_code for f in flags)


def lookup(flag: str) -> Flag:
    """The registered flag of ``flag`` (with or without its reason).

    Raises
    ------
    UnknownFlagError
        The code is not registered.
    """
    try:
        return REGISTRY[code(flag)]
    except KeyError:
        raise UnknownFlagError(f"unknown flag {code(flag)!r}: not one this version of BridgeSurvey raises "
                               "(a campaign from a newer version?)") from None


def severity(flag: str) -> str:
    """``info``, ``warning`` or ``problem`` (an unregistered code is an :class:`UnknownFlagError`).

    >>> severity("normal_refitted_in_epoch"), severity("missing"), severity("no_displacement: why")
    ('info', 'warning', 'problem')
    """
    return lookup(flag).severity


def meaning(flag: str) -> str:
    """The one-line meaning of a flag.

    >>> meaning("saturated")
    'intensity saturated on the target'
    """
    return lookup(flag).meaning


def renamed(flag: str) -> str:
    """A flag of an older version under its current code (the reason kept), others unchanged.

    >>> renamed("no-camera-data"), renamed("missing")
    ('no_camera_data', 'missing')
    """
    c = code(flag)
    return RENAMED[c] + flag[len(c):] if c in RENAMED else flag


def worst(flags: Iterable[str]) -> str | None:
    """The most serious severity among ``flags`` (None when there are none).

    >>> worst(["normal_refitted_in_epoch", "missing"])
    'warning'
    >>> worst([]) is None
    True
    """
    ranks = [SEVERITIES.index(severity(f)) for f in flags]
    return SEVERITIES[max(ranks)] if ranks else None


def count(flags: Iterable[str]) -> dict[str, int]:
    """How many flags of each severity.

    >>> count(["missing", "missing", "reference_inconsistent"])
    {'info': 0, 'warning': 2, 'problem': 1}
    """
    out = {s: 0 for s in SEVERITIES}
    for f in flags:
        out[severity(f)] += 1
    return out


def describe(flags: Iterable[str]) -> str:
    """Flags grouped by severity for a status line, most serious first.

    >>> describe(["normal_refitted_in_epoch", "missing"])
    'warning: missing; info: normal_refitted_in_epoch'
    """
    flags = list(flags)
    parts = []
    for s in reversed(SEVERITIES):
        these = [f for f in flags if severity(f) == s]
        if these:
            parts.append(f"{s}: " + ", ".join(these))
    return "; ".join(parts)

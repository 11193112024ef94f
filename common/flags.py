"""Every flag the product raises, declared once: its code, severity, meaning and the package that raises it.

Flags come from the centroids (a doubt about one target), the displacement computation (the reference
check, the deck normal, the frame), processing (an epoch that gave no result) and the camera
cross-check. They are not equally serious, and treating them alike turns every epoch red (alarm fatigue):

* **info** - a doubt the sigma already carries (a grazing view with its widened sigma, clipped intensities
  handled), or how a result was obtained (``normal_refitted_in_epoch``): nothing to do.
* **warning** - a value may be wrong beyond its sigma, or the surveyor must act: re-scan before leaving,
  inspect a target, check a reference (a target missing, a moved pier target left out, a second bright
  object in a window). Every warning says its action.
* **problem** - the epoch has no trustworthy result (no deck or pier targets measured, inconsistent
  references): act before the next visit.

Advice for the next visit (stand elsewhere to see a target better) is not a flag: it goes to the station
advisor, the plan and the field sheet.

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
        By consequence: *problem*, no trustworthy value; *warning*, a value may be wrong beyond its sigma or the
        surveyor must do something (re-scan before leaving, inspect a target, check a reference); *info*, a doubt
        the sigma already carries, or how a value was obtained.
    meaning : str
        One line for the report's flag table and the application's details.
    raised_by : str
        The module that raises it.
    action : str
        What the surveyor does about it, in plain words (every warning and problem has one; empty for info).
    words : str
        The flag as the report's body and the one-line visit summary say it (plural-ready noun phrase).
    """

    code: str
    severity: str
    meaning: str
    raised_by: str
    action: str = ""
    words: str = ""


REGISTRY: dict[str, Flag] = {}


def _flag(code: str, severity_: str, meaning: str, raised_by: str, *, action: str = "", words: str = "") -> str:
    if code in REGISTRY or severity_ not in SEVERITIES or code != code.lower() or "-" in code:
        raise ValueError(f"flag {code!r} declared twice, in another case or with a bad severity")
    REGISTRY[code] = Flag(code, severity_, meaning, raised_by, action, words or code.replace("_", " "))
    return code


# ---- a target in one fine scan (lidar.centroid)
FLAG_NOT_FOUND = _flag("not_found", WARNING, "target not found in its fine scan (occluded, removed or outside "
                       "the window)", "lidar.centroid", action="look at the target (occluded, fallen off?) and "
                       "re-scan its window before leaving", words="target not found")
FLAG_FEW_POINTS = _flag("few_points", INFO, "fewer points on the target than planned; its sigma is computed from "
                        "the points it has", "lidar.centroid", words="fewer points than planned")
FLAG_SECOND_OBJECT = _flag("second_bright_object", WARNING, "a second bright object beside the target was left "
                           "out (cable-tie-like contamination)", "lidar.centroid",
                           action="inspect the target and remove what shines beside it (a cable tie, a second "
                           "reflector); until then its value may carry the object's pull",
                           words="second bright object beside the target")
FLAG_CLIPPED = _flag("clipped_by_window", WARNING, "the target touches the edge of its scan window: its centroid "
                     "may be pulled toward the window's inside", "lidar.centroid",
                     action="re-scan the target with a larger window (check before leaving gives the re-scan plan)",
                     words="target clipped by its window")
FLAG_SATURATED = _flag("saturated", INFO, "intensity saturated on the target", "lidar.centroid",
                       words="saturated intensities")
FLAG_LOW_SEPARABILITY = _flag("low_separability", INFO, "target and background intensities overlap; the target's "
                              "points were taken by the disc's shape and its sigma from their scatter",
                              "lidar.centroid", words="target and background intensities overlap")
FLAG_SIZE = _flag("size_mismatch", WARNING, "bright area does not match the target diameter (a partly covered "
                  "disc, or another object)", "lidar.centroid",
                  action="inspect the target (dirt, a cover, damage) and check its diameter in the layout",
                  words="bright area not the target's size")
FLAG_OFF_EXPECTED = _flag("off_expected_position", INFO, "centroid away from the planned position (the plan's "
                          "positions come from the coarse scan, a few centimetres)", "lidar.centroid",
                          words="away from the planned position")
FLAG_LOW_CONTRAST = _flag("no_bright_target", WARNING, "no bright target in the window", "lidar.centroid",
                          action="look at the target (occluded, fallen off?) and re-scan its window before leaving",
                          words="no bright target in the window")
FLAG_NOT_COMPACT = _flag("no_compact_target", WARNING, "bright points but no disc-shaped cluster",
                         "lidar.centroid", action="look at the target (partly occluded, dirty, damaged?) and re-scan "
                         "its window before leaving", words="no disc-shaped target")
FLAG_GRAZING = _flag("grazing", INFO, "seen at grazing incidence: the disc is barely wider than the beam, its "
                     "sigma is widened for the bias of a partly resolved disc", "lidar.centroid",
                     words="grazing (sigma widened)")
FLAG_INCIDENCE_FROM_SCAN = _flag("incidence_from_scan", INFO, "the disc's outline in the fine scan shows a "
                                 "resolved disc where the layout's normal predicted a grazing view: the scan's "
                                 "incidence is used (the layout's normal for the target may be wrong)",
                                 "lidar.centroid", words="incidence from the scan, not the layout")
FLAG_CENTRES_APART = _flag("centres_apart", INFO, "the disc's centre weighted by its returns' intensities and "
                           "the thresholded disc's centre lie farther apart than the rim's sampling explains (a "
                           "stain or damage on the sheet, something dim beside the disc): the weighted centre is "
                           "kept with a sigma covering both", "lidar.centroid",
                           words="centres apart (sigma widened)")
FLAG_TRANSIENT_REMOVED = _flag("transient_corrected", INFO, "the surface around the target moved while part of its "
                               "window was scanned (a train, a lorry, wind): those points were moved back by the "
                               "surface's own departure, and the sigma widened for what that may leave",
                               "lidar.centroid", words="moved while scanned (corrected, sigma widened)")
FLAG_MOVED_DURING_SCAN = _flag("moved_during_scan", WARNING, "the surface around the target moved while most of "
                               "the target was scanned (a train, a lorry, wind): its value may be off by that "
                               "movement", "lidar.centroid", action="scan the window again when nothing crosses "
                               "the bridge (check before leaving gives the re-scan plan)",
                               words="moved while it was scanned")
FLAG_UNRESOLVED = _flag("unresolved", INFO, "not measured: at this range and incidence the disc is narrower "
                        "than the beam (measure it from another station: see 'bridgesurvey stations')",
                        "lidar.centroid", words="not resolvable from this station")

# ---- a target's displacement and the epoch's reference check (lidar.displacement, lidar.pier_moves)
FLAG_MISSING = _flag("missing", WARNING, "no value this epoch (target not found)", "lidar.displacement",
                     action="look at the target (occluded, fallen off?); re-scan it if still on site",
                     words="no value (target not found)")
FLAG_MISSING_AT_BASELINE = _flag("missing_at_baseline", INFO, "target not measured in the baseline epoch",
                                 "lidar.displacement", words="not measured in the baseline")
FLAG_REFERENCE_MOVED = _flag("reference_moved", WARNING, "a reference target moved and was left out of the "
                             "reference group", "lidar.displacement",
                             action="inspect the pier target (knocked, loose?) and replace it if it moved "
                             "('bridgesurvey reflector replace')", words="a pier target moved (left out)")
FLAG_REFERENCE_MISSING = _flag("reference_missing", WARNING, "a reference target was not found",
                               "lidar.displacement", action="look at the pier target (occluded, fallen off?); the "
                               "others carry the frame this visit", words="a pier target not found")
FLAG_REFERENCE_INCONSISTENT = _flag("reference_inconsistent", PROBLEM, "reference distances changed beyond "
                                    "tolerance", "lidar.displacement",
                                    action="inspect the pier targets: several moved; the displacements cannot be "
                                    "trusted until the reference group is sound", words="pier targets inconsistent")
FLAG_NORMAL_FROM_EPOCH = _flag("normal_refitted_in_epoch", INFO, "deck normal re-fitted in this epoch (fewer "
                               "references than needed, or the fit agreed with the carried normal)",
                               "lidar.displacement", words="deck normal re-fitted")
FLAG_REFERENCE_AMBIGUOUS = _flag("reference_change_ambiguous", WARNING, "the reference group changed and the "
                                 "moved target could not be singled out", "lidar.displacement",
                                 action="inspect the pier targets named and replace the one that moved",
                                 words="a pier target moved, which one is unclear")
FLAG_REFERENCE_UNRESOLVED = _flag("reference_move_unresolved", PROBLEM, "a reference target moved and neither the "
                                  "pier targets nor the deck's shape single it out: the displacements rest on the "
                                  "likeliest guess, or on the targets left once both suspects are left out, and may "
                                  "carry that move's tilt (errors of 5-15 sigma seen in simulation)",
                                  "lidar.displacement", action="inspect the pier targets named, replace the one that "
                                  "moved, and process again", words="a pier target moved and could not be found")
FLAG_REFERENCE_GEOMETRY_WEAK = _flag("reference_geometry_weak", PROBLEM, "the reference targets found (and the "
                                     "deck's sideways stability) cannot fix one of the frame's rotations: all on "
                                     "one line, or in one plane seen edge-on; the displacements are undetermined "
                                     "about that axis", "lidar.displacement",
                                     action="re-scan from a station that sees pier targets off that line, or add "
                                     "pier targets", words="pier targets on one line")

# ---- the field error budget: scale, range walk, drift (lidar.systematic, lidar.stage2)
FLAG_SCALE_UNDETERMINED = _flag("scale_undetermined", INFO, "the reference targets cannot determine the "
                                "atmosphere's range scale (too close together): its sigma is a plausible "
                                "atmosphere's",
                                "lidar.systematic.campaign_fit", words="range scale undetermined (sigma widened)")
FLAG_RANGE_WALK_UNDETERMINED = _flag("range_walk_undetermined", INFO, "too few or too alike stations to determine "
                                     "the retro-reflector range walk: sigma widened to what a plausible bias "
                                     "would cause",
                                     "lidar.systematic.campaign_fit", words="range walk undetermined (sigma widened)")
FLAG_FIELD_MISFIT = _flag("field_model_misfit", WARNING, "the target's centroid did not fit the campaign's field "
                          "model in a visit and was left out of its fit: something the model does not hold (a "
                          "range walk of that target's own, a knock, a cable tie) may bias the value beyond its "
                          "sigma; on every row of an epoch when it is a reference target", "lidar.stage2",
                          action="inspect the target named (cable tie, damage, a knock) and distrust its value "
                          "beyond its sigma", words="did not fit the field model")
FLAG_DRIFT_FROM_PLAN = _flag("drift_from_plan_times", INFO, "the fine scans carry no point times: the set-up's "
                             "drift was fitted on the plan's window order and time model",
                             "lidar.systematic.campaign_fit",
                             words="drift from the plan's times")
FLAG_TRANSIENTS_UNCHECKED = _flag("transients_unchecked", INFO, "the fine scans carry no point times: a train or a "
                                  "lorry crossing while a window was scanned could not be looked for", "lidar.stage2",
                                  words="no point times")
FLAG_DRIFT_BEYOND_SPEC = _flag("drift_beyond_tolerance", WARNING, "the set-up turned more during the visit than "
                               "the instrument allows for", "lidar.stage2",
                               action="check the tripod and the instrument's levelling, and re-scan",
                               words="the set-up drifted beyond tolerance")
FLAG_ATMOSPHERE_UNCORRECTED = _flag("atmosphere_not_corrected_by_instrument", INFO, "the range scale measured on "
                                    "the piers follows the air's temperature and pressure: the instrument did not "
                                    "correct for the atmosphere (the scale is corrected here)",
                                    "lidar.systematic.campaign_fit",
                                    words="atmosphere corrected here")
FLAG_ATMOSPHERE_CORRECTED = _flag("atmosphere_corrected_by_instrument", INFO, "no range scale left where the air "
                                  "predicts one: the instrument corrected for the atmosphere",
                                  "lidar.systematic.campaign_fit",
                                  words="atmosphere corrected by the instrument")
FLAG_ATMOSPHERE_DISAGREES = _flag("scale_disagrees_with_atmosphere", WARNING, "the range scale measured on the "
                                  "piers disagrees with what the air's temperature and pressure predict",
                                  "lidar.systematic.campaign_fit",
                                  action="check the air readings' times and the instrument's atmosphere setting; a "
                                  "pier that moved along the span also shows as a scale",
                                  words="range scale disagrees with the air")
FLAG_PIER_MOVED = _flag("pier_moved_along_span", WARNING, "the range scale measured on the piers disagrees with "
                        "the air, and one pier's targets moving along the span against the others' explains it: "
                        "that shift was fitted and taken out, and the visit's scale is the air's",
                        "lidar.systematic.pier_slide",
                        action="inspect the pier named (its bearings, its foundation) and its targets; the deck's "
                        "heights stand, its movements along the span are against the other piers",
                        words="a pier moved along the span")

# ---- an epoch with no result, or a history (lidar.stage2, lidar.setups)
FLAG_DECK_NOT_MEASURED = _flag("deck_not_measured", PROBLEM, "too few deck targets measured for a "
                               "displacement", "lidar.stage2", action="re-scan the deck targets (at least 3)",
                               words="too few deck targets measured")
FLAG_PIERS_NOT_MEASURED = _flag("piers_not_measured", PROBLEM, "no reference target measured in both this "
                                "epoch and the baseline", "lidar.stage2", action="re-scan the pier targets",
                                words="no pier target measured")
FLAG_NO_DISPLACEMENT = _flag("no_displacement", PROBLEM, "the displacements could not be computed (the reason "
                             "follows)", "lidar.stage2", action="act on the reason given, then process again",
                             words="no displacement computed")
FLAG_SETUP_NOT_JOINED = _flag("setup_not_joined", PROBLEM, "a set-up of the visit could not be joined to the "
                              "others (too few well-spread shared targets): its targets are left out",
                              "lidar.setups", action="re-scan from a station that shares at least three "
                              "well-spread targets with the others", words="a set-up could not be joined")
FLAG_SETUP_JOIN_MISFIT = _flag("setup_join_misfit", WARNING, "a target seen from two set-ups disagreed beyond its "
                               "sigmas and was measured from one of them only", "lidar.setups",
                               action="inspect the target named (moved between the set-ups? a cable tie?)",
                               words="set-ups disagreed on a target")
FLAG_SETUP_JOIN_WEAK = _flag("setup_join_weak", INFO, "a set-up was joined through targets seen only weakly (a "
                             "disc narrower than the beam, at grazing incidence) from it and from the set-ups before "
                             "it: the join's own error is large, and in the sigma of every value from that set-up "
                             "(sigma_frame_mm); a station that sees at least three of the others' targets well, or a "
                             "set-up between them, joins it better ('bridgesurvey stations --first')", "lidar.setups",
                             words="a set-up joined through weak sightings")
FLAG_SETUP_NOT_MEASURED = _flag("setup_not_measured", WARNING, "a set-up of the visit has no fine scans (or they "
                                "failed): the targets only it sees are missing", "lidar.stage2",
                                action="import its fine scans ('bridgesurvey add-fine --setup K') and process",
                                words="a set-up without fine scans")
FLAG_RESCAN_SKIPPED = _flag("rescan_skipped", WARNING, "the check before leaving asked for a re-scan of this target "
                            "(or of a reference target, or of the whole set-up); the visit was processed without one",
                            "lidar.stage2", action="distrust the value beyond its sigma; scan the target again at the "
                            "next visit, or add the re-scan's fine scans to this visit and process again",
                            words="processed without the re-scan the check asked for")
FLAG_CHAINED = _flag("chained_to_replaced_target", INFO, "history continues from a replaced target",
                     "lidar.stage2", words="history continued from a replaced target")
FLAG_DEPARTS = _flag("departs_from_prediction", WARNING, "the displacement departs from the design prediction "
                     "by more than its tolerance", "projects.results",
                     action="compare with the structure's state (inspection) and the design assumptions",
                     words="departs from the design prediction")

# ---- the camera cross-check (vision.crossval)
FLAG_NO_CAMERA_DATA = _flag("no_camera_data", INFO, "no camera samples around this LiDAR epoch",
                            "vision.crossval", words="no camera samples")
FLAG_FEW_CAMERA_SAMPLES = _flag("few_camera_samples", INFO, "few camera samples around this LiDAR epoch",
                                "vision.crossval", words="few camera samples")
FLAG_NO_LIDAR_VALUE = _flag("no_lidar_value", INFO, "no LiDAR displacement at this epoch", "vision.crossval",
                            words="no LiDAR value")

# ---- one frame of the dual-camera method (vision.compensation)
FLAG_MAIN_TARGET_MISSING = _flag("main_target_missing", WARNING, "the main camera's target was not found in "
                                 "this frame", "vision.compensation", action="check the main camera's view of its "
                                 "target (obstructed, out of focus?)", words="main camera's target not found")
FLAG_SUB_TARGET_MISSING = _flag("sub_target_missing", WARNING, "the sub-camera's checkerboard was not found in "
                                "this frame", "vision.compensation", action="check the sub-camera's view of the "
                                "checkerboard (obstructed, moved?)", words="sub-camera's checkerboard not found")

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


def action(flag: str) -> str:
    """What the surveyor does about a flag (empty for information).

    >>> action("grazing")
    ''
    """
    return lookup(flag).action


def words(flag: str) -> str:
    """The flag in plain words, for the report's body and one-line summaries.

    >>> words("grazing")
    'grazing (sigma widened)'
    """
    return lookup(flag).words


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


def _targets_of(flag: str) -> list[str]:
    """The targets a visit's flag names (``grazing: ... (M1 M5)`` or ``second_bright_object: R1``), or none."""
    c = code(flag)
    rest = flag[len(c):].lstrip(": ").strip()
    def ids(text: str) -> list[str]:  # target ids: words with a digit (M1, R12, P3a)
        words_ = text.split()
        return words_ if words_ and all(any(ch.isdigit() for ch in t) and t.replace("#", "").isalnum()
                                        for t in words_) else []

    if rest.endswith(")") and "(" in rest and not is_from_baseline(flag):
        return ids(rest[rest.rindex("(") + 1:-1])
    return ids(rest)


def summary(flags: Iterable[str]) -> str:
    """A visit's flags in one short phrase: each warning or problem in words with its targets, information counted.

    >>> summary(["normal_refitted_in_epoch", "grazing: the disc is 67 % of the beam's width (M5)",
    ...          "grazing: the disc is 61 % of the beam's width (M1)", "second_bright_object: R1"])
    'second bright object beside the target: R1; deck normal re-fitted; 2 targets grazing (sigma widened)'
    >>> summary([])
    '-'
    """
    by_code: dict[str, list[str]] = {}
    detail: dict[str, str] = {}
    order: list[str] = []
    for f in flags:
        c = code(f)
        if c not in by_code:
            by_code[c] = []
            order.append(c)
        found = _targets_of(f)
        by_code[c] += [t for t in found if t not in by_code[c]]
        if not found and f != c and not is_from_baseline(f):
            detail.setdefault(c, f[len(c):].lstrip(": ").strip())
    order.sort(key=lambda c: -SEVERITIES.index(REGISTRY[c].severity) if c in REGISTRY else 0)
    parts = []
    for c in order:
        ids, w = by_code[c], words(c)
        if REGISTRY[c].severity != INFO:
            parts.append(f"{w}: {' '.join(ids)}" if ids else f"{w} ({detail[c]})" if c in detail else w)
        else:
            parts.append(f"{len(ids)} target{'s' if len(ids) > 1 else ''} {w}" if ids else w)
    return "; ".join(parts) or "-"


def first_action(flags: Iterable[str]) -> str:
    """The action of the most serious flag among ``flags`` (empty when none asks for one)."""
    ranked = sorted((f for f in flags if severity(f) != INFO), key=lambda f: -SEVERITIES.index(severity(f)))
    return action(ranked[0]) if ranked else ""


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

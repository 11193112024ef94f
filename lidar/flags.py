"""How serious each flag is: info, warning or problem.

Flags come from the centroids (a doubt about one target), the displacement
computation (the reference check, the deck normal) and processing (an epoch
that gave no result). They are not equally serious, and treating them alike
turns every epoch red (alarm fatigue):

* **info** - how a result was obtained; nothing to do (``normal_refitted_in_epoch``).
* **warning** - a result exists but deserves a look (a target missing, a moved
  pier target left out, a second bright object in a window).
* **problem** - the epoch has no trustworthy result (no deck or pier targets
  measured, inconsistent references): act before the next visit.

A flag may carry its reason after a colon (``deck_not_measured: 0 of 6 deck
targets found``); its code is the part before it.
"""
from __future__ import annotations

from typing import Iterable, Optional

INFO, WARNING, PROBLEM = "info", "warning", "problem"
SEVERITIES = (INFO, WARNING, PROBLEM)

#: Epoch problems raised by processing (flag codes).
FLAG_DECK_NOT_MEASURED = "deck_not_measured"
FLAG_PIERS_NOT_MEASURED = "piers_not_measured"
FLAG_NO_DISPLACEMENT = "no_displacement"

SEVERITY: dict[str, str] = {
    # the deck normal and the history
    "normal_refitted_in_epoch": INFO,
    "missing_at_baseline": INFO,
    "chained_to_replaced_target": INFO,
    "saturated": INFO,
    # a result exists, look at it
    "missing": WARNING,
    "reference_missing": WARNING,
    "reference_moved": WARNING,
    "reference_change_ambiguous": WARNING,
    "not_found": WARNING,
    "few_points": WARNING,
    "second_bright_object": WARNING,
    "clipped_by_window": WARNING,
    "low_separability": WARNING,
    "size_mismatch": WARNING,
    "off_expected_position": WARNING,
    "no_bright_target": WARNING,
    "no_compact_target": WARNING,
    "departs_from_prediction": WARNING,
    # no trustworthy result
    "reference_inconsistent": PROBLEM,
    FLAG_DECK_NOT_MEASURED: PROBLEM,
    FLAG_PIERS_NOT_MEASURED: PROBLEM,
    FLAG_NO_DISPLACEMENT: PROBLEM,
}


def code(flag: str) -> str:
    """The flag's code, without its reason.

    >>> code("deck_not_measured: 0 of 6 deck targets found")
    'deck_not_measured'
    """
    return flag.split(":", 1)[0].strip()


def severity(flag: str) -> str:
    """``info``, ``warning`` or ``problem``; a flag this version does not know is a warning.

    >>> severity("normal_refitted_in_epoch"), severity("missing"), severity("no_displacement: why")
    ('info', 'warning', 'problem')
    """
    return SEVERITY.get(code(flag), WARNING)


def worst(flags: Iterable[str]) -> Optional[str]:
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

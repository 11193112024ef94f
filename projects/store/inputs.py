"""Checks of thin or odd inputs, so that they get their word instead of passing in silence.

* A layout target that no station near the others could reach (farther from the other targets than
  the scanner's range) is a warning at ``init``, at ``plan`` and in ``status``: it would be planned
  as a window giving no points and reported missing every epoch.
* An epoch dated more than :data:`DATE_SPAN_YEARS` years from the campaign's other epochs (outside
  :data:`PLAUSIBLE_YEARS`, for the first epoch) is refused unless the user says the date is right
  (``--allow-date``): a typed 1900 or 2200 would otherwise become a baseline or stretch every time axis.
"""
from __future__ import annotations

import datetime as dt
from collections.abc import Sequence

import numpy as np

from common.errors import InputError

#: How far (years) an epoch may lie from the campaign's other epochs before its date must be confirmed.
DATE_SPAN_YEARS = 3.0
#: The years a campaign's first epoch may fall in without confirmation (first and last).
PLAUSIBLE_YEARS = (1980, 2099)
#: The years a date-time as nanoseconds since 1970 in 64 bits holds (every time axis of the product: series,
#: histories, plots): a date outside them is refused even with ``--allow-date``.
COMPUTABLE_YEARS = (1678, 2261)


def check_computable(when: str) -> None:
    """Refuse a date the product cannot compute with (outside :data:`COMPUTABLE_YEARS`), whatever the options.

    >>> check_computable("0001-01-01")
    Traceback (most recent call last):
    ...
    common.errors.InputError: date 0001-01-01 is outside the years BridgeSurvey computes with (1678 to 2261), ...
    """
    w = _aware(when)
    if not COMPUTABLE_YEARS[0] <= w.year <= COMPUTABLE_YEARS[1]:
        raise InputError(f"date {w.date()} is outside the years BridgeSurvey computes with ({COMPUTABLE_YEARS[0]} to "
                         f"{COMPUTABLE_YEARS[1]}), even with --allow-date; check --date")


def _aware(text: str) -> dt.datetime:
    value = dt.datetime.fromisoformat(text)
    return value if value.tzinfo is not None else value.replace(tzinfo=dt.UTC)


def check_epoch_date(when: str, others: Sequence[str]) -> None:
    """Refuse an epoch date far from the others, or outside :data:`PLAUSIBLE_YEARS` (see the module notes).

    Dates are ISO 8601 text. The first epoch of a campaign has no others: only the plausible years
    apply (a typed 1900 or 2200), so a campaign of archived scans can start at any real date.

    Examples
    --------
    >>> check_epoch_date("2026-04-06", ["2026-03-02", "2026-03-09"])
    >>> check_epoch_date("1900-01-01", ["2026-03-02", "2026-03-09"])
    Traceback (most recent call last):
    ...
    common.errors.InputError: epoch date 1900-01-01 is 126 years before the campaign's other epochs (2026-03-02 to 2026-03-09); check --date, or give --allow-date if it is right
    >>> check_epoch_date("2200-01-01", [])
    Traceback (most recent call last):
    ...
    common.errors.InputError: epoch date 2200-01-01 is not a plausible date for a scan (years 1980 to 2099); check --date, or give --allow-date if it is right
    """
    w = _aware(when)
    hint = "check --date, or give --allow-date if it is right"
    if not others:
        if not PLAUSIBLE_YEARS[0] <= w.year <= PLAUSIBLE_YEARS[1]:
            raise InputError(f"epoch date {w.date()} is not a plausible date for a scan (years {PLAUSIBLE_YEARS[0]} "
                             f"to {PLAUSIBLE_YEARS[1]}); {hint}")
        return
    dates = sorted(_aware(t) for t in others)
    lo, hi = dates[0], dates[-1]
    span = dt.timedelta(days=365.25 * DATE_SPAN_YEARS)
    if lo - span <= w <= hi + span:
        return
    gap = (lo - w) if w < lo else (w - hi)
    where = "before" if w < lo else "after"
    raise InputError(f"epoch date {w.date()} is {gap.days / 365.25:.0f} years {where} the campaign's other epochs "
                     f"({lo.date()} to {hi.date()}); {hint}")


#: Fewer reference targets than this is a warning (2 are accepted: the least a frame needs).
REFERENCES_ADVISED = 3


def few_references(ids: Sequence[str]) -> list[str]:
    """A warning when the layout has fewer than :data:`REFERENCES_ADVISED` reference targets (``ids``: theirs).

    Examples
    --------
    >>> print(few_references(["R1", "R2"])[0])  # doctest: +NORMALIZE_WHITESPACE
    the layout has only 2 reference targets (R1, R2): when one of them moves, processing can tell that the
    distance between them changed but not which one moved, and the epoch's displacements cannot be trusted;
    glue at least one more on a pier (two on each pier is best)
    """
    if len(ids) >= REFERENCES_ADVISED:
        return []
    return [f"the layout has only {len(ids)} reference targets ({', '.join(ids)}): when one of them moves, "
            "processing can tell that the distance between them changed but not which one moved, and the epoch's "
            "displacements cannot be trusted; glue at least one more on a pier (two on each pier is best)"]


def unreachable_targets(ids: Sequence[str], xyz: np.ndarray, *, max_range_m: float, scanner: str = "the scanner"
                        ) -> list[str]:
    """One warning per target farther from the other targets than the scanner reaches.

    Parameters
    ----------
    ids : sequence of str, length N
    xyz : ndarray, shape (N, 3)
        Target positions in the layout frame, metres.
    max_range_m : float, keyword-only
        The scanner's range, metres.
    scanner : str, keyword-only
        Its name, for the message.

    Examples
    --------
    >>> xyz = np.array([[0, 0, 0], [40, 0, 0], [20, 1, -1], [10000, 0, 0]], float)
    >>> for w in unreachable_targets(["R1", "R2", "M1", "M9"], xyz, max_range_m=1400):
    ...     print(w)  # doctest: +NORMALIZE_WHITESPACE
    layout target M9 is 9,960 m from the other targets (which span 40 m), beyond the scanner's range
    of 1,400 m: no station near the bridge can reach it; check its coordinates in the layout
    """
    pts = np.asarray(xyz, dtype=float).reshape(-1, 3)
    out: list[str] = []
    if len(pts) < 2 or not (np.isfinite(max_range_m) and max_range_m > 0):
        return out
    for k, rid in enumerate(ids):
        others = np.delete(pts, k, axis=0)
        lo, hi = others.min(axis=0), others.max(axis=0)
        d = float(np.linalg.norm(np.maximum(np.maximum(lo - pts[k], pts[k] - hi), 0.0)))
        if d > max_range_m:
            extent = float(np.linalg.norm(hi - lo))
            out.append(f"layout target {rid} is {d:,.0f} m from the other targets (which span {extent:,.0f} m), "
                       f"beyond {scanner}'s range of {max_range_m:,.0f} m: no station near the bridge can reach "
                       "it; check its coordinates in the layout")
    return out

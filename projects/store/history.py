"""Displacement histories: each target's stored displacements as arrays in millimetres.

One :class:`DisplacementHistory` per target is what the application's plot, the report's figures,
the campaign figures, the cross-validation, the prediction alignment and the analysis all read, so
they group, date and scale the stored values the same way.
"""
from __future__ import annotations

import datetime as dt
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from common.errors import InputError
from common.flags import PROBLEM, WARNING, worst
from projects.store.records import DisplacementRecord


def ns_of(when: dt.datetime) -> int:
    """A timezone-aware date-time as nanoseconds since 1970 (UTC), to the microsecond.

    A date-time outside what 64 bits of nanoseconds hold (an epoch dated in year 1 by mistake) is an
    :class:`InputError` naming it, never an overflow.
    """
    ns = int(round(when.timestamp() * 1e6)) * 1000
    if not -(2**63) < ns < 2**63:
        raise InputError(f"date {when.isoformat()} is outside the years BridgeSurvey computes with (1678 to 2261); "
                         "an epoch with such a date cannot be shown on a time axis: check the epochs' dates with "
                         "'bridgesurvey status'")
    return ns


@dataclass(frozen=True)
class DisplacementHistory:
    """One target's displacement at every processed epoch, oldest first.

    Attributes
    ----------
    reflector : str
    epochs : tuple of str, length N
        Epoch labels.
    times : tuple of datetime.datetime, length N
        The epochs' date-times (timezone-aware).
    displacement_mm : ndarray, shape (N,)
        Vertical displacement from the baseline, millimetres, positive up; NaN where the epoch has none.
    sigma_mm : ndarray, shape (N,)
        Its standard uncertainty, millimetres (0 at the baseline itself; NaN where there is no value).
    flags, epoch_flags : tuple of tuple of str, length N
        The target's own flags and its epoch's, per epoch.
    baselines : tuple of str, length N
    limit : projects.limits.Limit or None
        The warning and alarm limits that apply to the target.
    """

    reflector: str
    epochs: tuple[str, ...]
    times: tuple[dt.datetime, ...]
    displacement_mm: np.ndarray
    sigma_mm: np.ndarray
    flags: tuple[tuple[str, ...], ...]
    epoch_flags: tuple[tuple[str, ...], ...]
    baselines: tuple[str, ...]
    limit: object | None = None

    def __len__(self) -> int:
        return len(self.epochs)

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask, shape (N,): epochs with a displacement."""
        return np.isfinite(self.displacement_mm)

    @property
    def flagged(self) -> np.ndarray:
        """Boolean mask, shape (N,): epochs where the target carries a warning or a problem of its own.

        Information (a doubt its sigma carries, how it was obtained) does not mark a value.
        """
        return np.array([worst(f) in (WARNING, PROBLEM) for f in self.flags], dtype=bool)

    @property
    def time_ns(self) -> np.ndarray:
        """Epoch times as int64 nanoseconds since 1970 (UTC), shape (N,)."""
        return np.array([ns_of(t) for t in self.times], dtype=np.int64)

    def select(self, mask) -> DisplacementHistory:
        """The history at the epochs where ``mask`` (boolean or index array) holds."""
        idx = np.arange(len(self))[np.asarray(mask)]
        pick = [int(i) for i in idx]
        return DisplacementHistory(
            self.reflector, tuple(self.epochs[i] for i in pick), tuple(self.times[i] for i in pick),
            self.displacement_mm[idx], self.sigma_mm[idx], tuple(self.flags[i] for i in pick),
            tuple(self.epoch_flags[i] for i in pick), tuple(self.baselines[i] for i in pick), self.limit)

    def measured(self) -> DisplacementHistory:
        """Only the epochs with a displacement."""
        return self.select(self.valid)

    def thinned(self, max_points: int) -> DisplacementHistory:
        """Every k-th epoch so that at most ``max_points`` remain (for drawing long series)."""
        if len(self) <= max_points:
            return self
        return self.select(np.arange(0, len(self), int(np.ceil(len(self) / max_points))))


def histories_from_records(records: Iterable[DisplacementRecord], limits: Mapping[str, object] | None = None,
                           *, targets: Sequence[str] | None = None) -> dict[str, DisplacementHistory]:
    """Group stored displacement records by target (records in epoch order).

    Examples
    --------
    >>> from projects.store.records import DisplacementRecord
    >>> recs = [DisplacementRecord("e1", "2026-03-02T09:00:00+00:00", "M1", 0.0, 0.0, (), (), "e1"),
    ...         DisplacementRecord("e2", "2026-03-09T09:00:00+00:00", "M1", -0.0021, 0.0001, (), (), "e1")]
    >>> h = histories_from_records(recs)["M1"]
    >>> h.epochs, h.displacement_mm.round(3).tolist(), h.sigma_mm.round(3).tolist()
    (('e1', 'e2'), [0.0, -2.1], [0.0, 0.1])

    Parameters
    ----------
    records : iterable of DisplacementRecord
        As :meth:`projects.store.Campaign.displacements` returns them (metres).
    limits : mapping reflector -> Limit or None, optional
    targets : sequence of str, optional
        Only these targets (default: every target with a record), sorted by name.
    """
    grouped: dict[str, list[DisplacementRecord]] = {}
    for r in records:
        if targets is None or r.reflector in targets:
            grouped.setdefault(r.reflector, []).append(r)
    out = {}
    for rid in sorted(grouped):
        rs = grouped[rid]
        out[rid] = DisplacementHistory(
            rid, tuple(r.epoch for r in rs), tuple(r.when for r in rs),
            np.array([np.nan if r.displacement_m is None else r.displacement_m * 1e3 for r in rs], dtype=float),
            np.array([np.nan if r.displacement_m is None else (r.sigma_m or 0.0) * 1e3 for r in rs], dtype=float),
            tuple(r.flags for r in rs), tuple(r.epoch_flags for r in rs), tuple(r.baseline for r in rs),
            (limits or {}).get(rid))
    return out


def histories(c, *, targets: Sequence[str] | None = None) -> dict[str, DisplacementHistory]:
    """Every target's history in campaign ``c`` (a :class:`projects.store.Campaign`), with its limits."""
    records = c.displacements()
    ids = {r.reflector for r in records} if targets is None else set(targets)
    return histories_from_records(records, {rid: c.limit_for(rid) for rid in sorted(ids)}, targets=targets)

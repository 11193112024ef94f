"""A pair of set-ups for one visit: the best second station given the first.

When one station cannot see the whole bridge well (a long bridge, a pier hiding targets), a visit takes two
set-ups, joined through the targets both see (:mod:`lidar.setups`). Given the evaluated
stations (:func:`projects.onsite.stations.advise_stations`) and the first one (by default the best), the second
is the one whose predicted sigmas most improve the worst deck target: each target's sigma from the pair is
its two stations' combined by inverse variance (one station's when only one sees it), and the pair must share
at least three well-spread targets to be joined at all. The join's own uncertainty is not in these
predictions; processing reports it in each displacement's frame term. Shared targets are those both stations see
well (not weak), as the planner's ties are. When no second station joins the first (two stations near the ends of
a 150 m bridge see each other's targets only from afar), :func:`propose_three` proposes three set-ups, each joined
to those before it.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from lidar.layout import Layout
from lidar.setups import MIN_SHARED, MIN_SPREAD_M, spread_m
from lidar.stations import StationPrediction


@dataclass(frozen=True)
class StationPair:
    """Two set-ups of one visit and what they would deliver together (sigmas in mm)."""

    first: StationPrediction
    second: StationPrediction
    predicted_sigma_mm: dict
    hidden: tuple[str, ...]
    shared: tuple[str, ...]

    @property
    def worst_sigma_mm(self) -> float:
        """The largest predicted sigma of the pair (inf when a deck target is hidden from both)."""
        return math.inf if self.hidden or not self.predicted_sigma_mm else max(self.predicted_sigma_mm.values())

    def to_json(self) -> dict:
        worst = self.worst_sigma_mm
        return {"first": self.first.to_json(), "second": self.second.to_json(),
                "worst_sigma_mm": None if math.isinf(worst) else round(worst, 4),
                "predicted_sigma_mm": {k: round(float(v), 4) for k, v in self.predicted_sigma_mm.items()},
                "hidden": list(self.hidden), "shared": list(self.shared),
                "seconds": round(float(self.first.seconds + self.second.seconds), 1)}


def _sharp(station: StationPrediction, layout: Layout) -> set[str]:
    """The targets a station sees well: not hidden, not weak.

    A weak sighting joins nothing: the planner's ties want targets seen well from both set-ups
    (:mod:`lidar.visit_plan`).
    """
    return {t for t in layout.ids if t not in station.hidden} - set(station.weak)


def _shared(before: set[str], station: StationPrediction, layout: Layout) -> tuple[str, ...] | None:
    """What ``station`` shares well with the set-ups before it (``before``: what they see well), when that joins it.

    None when fewer than three such targets, or when they lie on a line.
    """
    sharp = _sharp(station, layout)
    shared = [t for t in layout.ids if t in before and t in sharp]
    if len(shared) < MIN_SHARED or spread_m(np.array([layout.xyz[layout.index(t)] for t in shared])) < MIN_SPREAD_M:
        return None
    return tuple(shared)


def _deck_sigmas(stations: Sequence[StationPrediction], layout: Layout) -> tuple[dict, tuple[str, ...]]:
    """Each deck target's sigma from the stations together (inverse variance), and those none of them sees."""
    sig = {}
    deck = [t for t, g in zip(layout.ids, layout.groups, strict=False) if g == "measurement"]
    for t in deck:
        parts = [s.predicted_sigma_mm[t] for s in stations if t in s.predicted_sigma_mm]
        if parts:
            sig[t] = float(sum(p ** -2 for p in parts) ** -0.5)
    return sig, tuple(t for t in deck if t not in sig)


def combine(first: StationPrediction, second: StationPrediction, layout: Layout) -> StationPair | None:
    """What two stations give together.

    None when they cannot be joined: fewer than three well-spread targets seen well from both.
    """
    shared = _shared(_sharp(first, layout), second, layout)
    if shared is None:
        return None
    sig, hidden = _deck_sigmas((first, second), layout)
    return StationPair(first, second, sig, hidden, shared)


@dataclass(frozen=True)
class StationChain:
    """Three set-ups of one visit, each joined to those before it, and what they deliver (sigmas in mm).

    Proposed when no second station can be joined to the first: on a long bridge two stations near its ends see
    each other's targets only from afar (weak or not at all), and a set-up between them joins both.
    """

    stations: tuple[StationPrediction, ...]
    predicted_sigma_mm: dict
    hidden: tuple[str, ...]
    shared: tuple[tuple[str, ...], ...]  # set-up 2, 3...: the targets it shares well with those before it

    @property
    def worst_sigma_mm(self) -> float:
        """The largest predicted sigma (inf when a deck target is hidden from all)."""
        return math.inf if self.hidden or not self.predicted_sigma_mm else max(self.predicted_sigma_mm.values())

    def to_json(self) -> dict:
        worst = self.worst_sigma_mm
        return {"stations": [s.to_json() for s in self.stations],
                "worst_sigma_mm": None if math.isinf(worst) else round(worst, 4),
                "predicted_sigma_mm": {k: round(float(v), 4) for k, v in self.predicted_sigma_mm.items()},
                "hidden": list(self.hidden), "shared": [list(s) for s in self.shared],
                "seconds": round(float(sum(s.seconds for s in self.stations)), 1)}


def chain(stations: Sequence[StationPrediction], layout: Layout) -> StationChain | None:
    """What the stations give together, in their order; None when one cannot be joined to those before it."""
    before = _sharp(stations[0], layout)
    shared = []
    for s in stations[1:]:
        got = _shared(before, s, layout)
        if got is None:
            return None
        shared.append(got)
        before |= _sharp(s, layout)
    sig, hidden = _deck_sigmas(stations, layout)
    return StationChain(tuple(stations), sig, hidden, tuple(shared))


def propose_three(stations: Sequence[StationPrediction], layout: Layout, *, first: StationPrediction | None = None,
                  sigma_mm: float | None = None) -> StationChain | None:
    """Three set-ups from the first (default: the best single station), each joined to those before it.

    Asked for when no second station can be joined to the first. Ranked as pairs are: the fewest deck targets
    hidden from all (and, with ``sigma_mm``, above the sigma asked), then the smallest worst-target sigma, then the
    shortest total time. None when no three join.
    """
    usable = [s for s in stations if s.predicted_sigma_mm]
    if not usable:
        return None
    first = first or usable[0]
    sharp_first = _sharp(first, layout)
    best, best_key = None, None
    for m in usable:
        if m is first or _shared(sharp_first, m, layout) is None:
            continue
        for t in usable:
            if t is first or t is m:
                continue
            c = chain((first, m, t), layout)
            if c is None:
                continue
            key = (len(above(c, sigma_mm)), len(c.hidden), c.worst_sigma_mm,
                   sum(s.seconds for s in c.stations), m.xyz_layout, t.xyz_layout)
            if best_key is None or key < best_key:
                best, best_key = c, key
    return best


def short_of(station: StationPrediction, layout: Layout, sigma_mm: float | None = None) -> dict[str, str]:
    """The deck targets a station cannot measure to the sigma asked, each with why (hidden, weak, or its sigma).

    Without ``sigma_mm`` only the hidden and the weak ones (seen at grazing incidence, with a widened sigma).
    """
    out = {}
    for t, g in zip(layout.ids, layout.groups, strict=False):
        if g != "measurement":
            continue
        if t not in station.predicted_sigma_mm:
            out[t] = station.reasons.get(t, "hidden")
        elif t in station.weak:
            out[t] = f"weak from here (sigma {station.predicted_sigma_mm[t]:.3f} mm)"
        elif sigma_mm is not None and station.predicted_sigma_mm[t] > sigma_mm:
            out[t] = f"sigma {station.predicted_sigma_mm[t]:.3f} mm"
    return out


def above(pair: StationPair | StationChain, sigma_mm: float | None) -> tuple[str, ...]:
    """The deck targets a pair (or chain) still cannot measure to the sigma asked (hidden from all, or above it)."""
    if sigma_mm is None:
        return pair.hidden
    return pair.hidden + tuple(t for t, s in pair.predicted_sigma_mm.items() if s > sigma_mm)


def propose_pair(stations: Sequence[StationPrediction], layout: Layout, *,
                 first: StationPrediction | None = None, sigma_mm: float | None = None) -> StationPair | None:
    """The best second set-up given the first (default: the best single station), or None when no pair joins.

    The second is the station whose pair with the first leaves the fewest deck targets hidden from both (and, with
    ``sigma_mm``, above the sigma asked), then has the smallest worst-target sigma, then the shortest total time.
    """
    usable = [s for s in stations if s.predicted_sigma_mm]
    if not usable:
        return None
    first = first or usable[0]
    pairs = [p for s in usable if s is not first and (p := combine(first, s, layout)) is not None]
    if not pairs:
        return None
    return min(pairs, key=lambda p: (len(above(p, sigma_mm)), len(p.hidden), p.worst_sigma_mm,
                                     p.first.seconds + p.second.seconds, p.second.xyz_layout))

"""A pair of set-ups for one visit: the best second station given the first.

When one station cannot see the whole bridge well (a long bridge, a pier hiding targets), a visit takes two
set-ups, joined through the targets both see (:mod:`lidar.setups`). Given the evaluated
stations (:func:`projects.onsite.stations.advise_stations`) and the first one (by default the best), the second
is the one whose predicted sigmas most improve the worst deck target: each target's sigma from the pair is
its two stations' combined by inverse variance (one station's when only one sees it), and the pair must share
at least three well-spread targets to be joined at all. The join's own uncertainty is not in these
predictions; processing reports it in each displacement's frame term.
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


def combine(first: StationPrediction, second: StationPrediction, layout: Layout) -> StationPair | None:
    """What two stations give together; None when they cannot be joined (fewer than three well-spread shared targets)."""
    seen_a = [t for t in layout.ids if t not in first.hidden]
    seen_b = set(t for t in layout.ids if t not in second.hidden)
    shared = [t for t in seen_a if t in seen_b]
    if len(shared) < MIN_SHARED or spread_m(np.array([layout.xyz[layout.index(t)] for t in shared])) < MIN_SPREAD_M:
        return None
    sig = {}
    deck = [t for t, g in zip(layout.ids, layout.groups, strict=False) if g == "measurement"]
    for t in deck:
        parts = [s.predicted_sigma_mm[t] for s in (first, second) if t in s.predicted_sigma_mm]
        if parts:
            sig[t] = float(sum(p ** -2 for p in parts) ** -0.5)
    hidden = tuple(t for t in deck if t not in sig)
    return StationPair(first, second, sig, hidden, tuple(shared))


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


def above(pair: StationPair, sigma_mm: float | None) -> tuple[str, ...]:
    """The deck targets a pair still cannot measure to the sigma asked (hidden from both, or above it)."""
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

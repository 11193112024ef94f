"""What the 3-D view draws of a cloud: which points within its budget, and the colour scale (no Qt here).

A software-OpenGL display redraws about three million points a second; a view that must stay
responsive draws at most :data:`POINT_BUDGET` points when still and :data:`INTERACTIVE_POINTS` while it
moves (the computations always use every point).

The colour scale of a change cloud comes from the structure, not from the whole scene: the far ground
and vegetation change by centimetres between visits (grass, puddles, a registration that is exact only
at the bridge), and a scale set by them washes out a deck that moved by millimetres.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Points drawn when the view is still.
POINT_BUDGET = 400_000
#: Points drawn while the view is being rotated or zoomed.
INTERACTIVE_POINTS = 100_000
#: Percentile of |change| on the structure that the colour scale reaches.
SCALE_PERCENTILE = 98.0


def budget_indices(n: int, budget: int = POINT_BUDGET) -> np.ndarray:
    """Every ``ceil(n / budget)``-th index of ``n`` points (all of them within the budget).

    >>> budget_indices(10, 4)
    array([0, 3, 6, 9])
    """
    step = max(1, int(np.ceil(n / max(budget, 1))))
    return np.arange(0, n, step)


def structure_mask(xyz: np.ndarray, markers_xyz: np.ndarray, *, margin_m: float = 1.0) -> np.ndarray:
    """Points of an (N, 3) cloud within ``margin_m`` of the box around the targets (the deck and piers).

    Without targets every point counts.
    """
    if not len(markers_xyz):
        return np.ones(len(xyz), bool)
    lo = markers_xyz.min(axis=0) - margin_m
    hi = markers_xyz.max(axis=0) + margin_m
    return np.all((xyz >= lo) & (xyz <= hi), axis=1)


@dataclass(frozen=True)
class ChangeScale:
    """A symmetric colour scale: ±``limit`` (the cloud's unit), from ``n_points`` points of ``source``."""

    limit: float
    source: str
    n_points: int

    @property
    def legend(self) -> str:
        return (f"colours ±{self.limit:.1f} mm: {SCALE_PERCENTILE:g}th percentile of the absolute change on "
                f"{self.source} ({self.n_points:,} points)")


def change_scale(xyz: np.ndarray, values: np.ndarray, markers_xyz: np.ndarray, *, min_points: int = 200) -> ChangeScale:
    """The colour scale of a signed change cloud: symmetric about zero, reaching the
    :data:`SCALE_PERCENTILE` th percentile of |change| on the deck and piers (every point when too few
    of them have a value).

    >>> xyz = np.zeros((1000, 3)); xyz[500:, 0] = 50.0           # half the points far from the target
    >>> v = np.r_[np.linspace(-4, 4, 500), np.full(500, 9.7)]    # the far half changes by 9.7 mm
    >>> s = change_scale(xyz, v, np.zeros((1, 3)))
    >>> round(s.limit, 2), s.source
    (3.92, 'the deck and piers')
    """
    finite = np.isfinite(values)
    on = structure_mask(xyz, markers_xyz) & finite
    source = "the deck and piers"
    if on.sum() < min_points:
        on, source = finite, "every point"
    if not on.any():
        return ChangeScale(1.0, "no point (no value)", 0)
    limit = float(np.percentile(np.abs(values[on]), SCALE_PERCENTILE))
    return ChangeScale(max(limit, 0.1), source, int(on.sum()))

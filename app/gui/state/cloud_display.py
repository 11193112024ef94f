"""What the 3-D view draws of a cloud: which points within its budget, and the colour scale (no Qt here).

A software-OpenGL display (Xvfb, a laptop without a driver) takes about 0.15 s to draw 100 k points and as
much again to take them over; the interface thread must answer within 0.2-0.5 s, so the view draws at most
:data:`POINT_BUDGET` points when still and :data:`INTERACTIVE_POINTS` while it moves (the computations always
use every point). Everything but the hand-over to VTK is prepared in the worker (:func:`prepare_cloud`):
the thinning, the offset, float32 coordinates, the colour limits and the level of detail's subset.

The colour scale of a change cloud comes from the structure, not from the whole scene: the far ground
and vegetation change by centimetres between visits (grass, puddles, a registration that is exact only
at the bridge), and a scale set by them washes out a deck that moved by millimetres.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from common.progress import ProgressCallback, report

if TYPE_CHECKING:  # the type only: the state module stays light
    from projects.outputs.inspection import DisplayCloud

#: Points drawn when the view is still (0.15-0.3 s a frame with software OpenGL on two busy cores; 150 k points
#: held the interface up to 0.8 s on the first frame of a cloud).
POINT_BUDGET = 100_000
#: Points drawn while the view is being rotated or zoomed.
INTERACTIVE_POINTS = 40_000
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


@dataclass(frozen=True, eq=False)
class PreparedCloud:
    """A display cloud ready for VTK: what the 3-D view hands over on the interface thread, nothing more.

    ``cloud`` is the :class:`projects.outputs.inspection.DisplayCloud` it came from; ``xyz`` (float32, the
    drawn points less ``offset``, so millimetres survive near the bridge) and ``values`` are the drawn points;
    ``lod`` indexes the subset drawn while the view moves (None when every drawn point is drawn then too);
    ``clim`` the colour limits, ``scale`` the change cloud's :class:`ChangeScale` (None for intensity);
    ``markers`` the targets' positions less ``offset``.
    """

    cloud: DisplayCloud
    xyz: np.ndarray
    values: np.ndarray
    offset: np.ndarray
    lod: np.ndarray | None
    clim: tuple[float, float]
    scale: ChangeScale | None
    markers: np.ndarray

    @property
    def change(self) -> bool:
        return self.scale is not None

    @property
    def drawn(self) -> int:
        return len(self.xyz)

    @property
    def thinned(self) -> bool:
        return self.drawn < len(self.cloud.xyz)

    @property
    def status(self) -> str:
        """One line for the status bar: what is drawn of how many points."""
        c = self.cloud
        what = "change" if self.change else "scan"
        if self.drawn < c.n_total:
            return (f"3-D view: {self.drawn:,} of the {c.n_total:,} points of the {what} drawn (thinned for "
                    f"display to stay responsive; every point was used), {INTERACTIVE_POINTS:,} while it moves")
        return f"3-D view: all {c.n_total:,} points of the {what} drawn"


def prepare_cloud(cloud, *, budget: int = POINT_BUDGET, progress: ProgressCallback | None = None) -> PreparedCloud:
    """Thin a :class:`projects.outputs.inspection.DisplayCloud` to ``budget`` points and prepare its drawing.

    Runs in the worker; the 3-D view only hands the arrays over to VTK.

    >>> from types import SimpleNamespace
    >>> xyz = np.column_stack([np.arange(1000.0), np.zeros(1000), np.zeros(1000)]) + 1e5
    >>> c = SimpleNamespace(xyz=xyz, values=np.linspace(0, 1, 1000), value_name="intensity", n_total=5000,
    ...                     marker_xyz=np.zeros((0, 3)))
    >>> p = prepare_cloud(c, budget=300)
    >>> p.drawn, p.xyz.dtype.name, p.change, float(p.offset[0]) > 0
    (250, 'float32', False, True)
    """
    keep = budget_indices(len(cloud.xyz), budget)
    xyz = cloud.xyz[keep]
    values = np.asarray(cloud.values)[keep]
    offset = np.median(xyz, axis=0) if len(xyz) else np.zeros(3)
    if cloud.value_name == "intensity":
        scale = None
        lo, hi = np.nanpercentile(values, [1, 99.5]) if np.isfinite(values).any() else (0.0, 1.0)
        clim = (float(lo), float(max(hi, lo + 1e-3)))
    else:  # signed change: symmetric about zero, scaled on the structure (from every point the job kept)
        scale = change_scale(cloud.xyz, np.asarray(cloud.values), cloud.marker_xyz)
        clim = (-scale.limit, scale.limit)
    lod = budget_indices(len(keep), INTERACTIVE_POINTS) if len(keep) > INTERACTIVE_POINTS else None
    report(progress, 1.0, f"{len(keep):,} points ready to draw")
    return PreparedCloud(cloud, (xyz - offset).astype(np.float32), values.astype(np.float32), offset, lod, clim,
                         scale, np.asarray(cloud.marker_xyz, float).reshape(-1, 3) - offset)

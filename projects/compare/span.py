"""Span coordinates of a comparison: station along the layout's x from the first pier, lateral offset, height.

The campaign frame (the baseline's scanner frame) is tied to the layout's frame by a rigid fit of the
baseline's measured target centroids onto the layout's coordinates (a few centimetres: enough for stations
and offsets, while heights are only ever differenced between epochs). Stations run along the layout's bridge
axis, oriented with the layout's x, so a layout with x along the span from the first pier gives its own x as
the station; heights are along the layout's up direction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.rigid import Transform, fit_rigid
from lidar.layout import Layout, bridge_axis
from projects.store.errors import CampaignError
from registration.profile import RegistrationSigma


@dataclass(frozen=True, eq=False)
class SpanFrame:
    """Campaign frame -> span coordinates (station, lateral offset, height), metres.

    Attributes
    ----------
    to_layout : Transform
        Campaign frame -> layout frame.
    axis, side, up : (3,) arrays
        Unit vectors of the span coordinates in the layout frame.
    first_pier_m, last_pier_m : float
        Stations of the reference targets nearest each end (the piers).
    """

    to_layout: Transform
    axis: np.ndarray
    side: np.ndarray
    up: np.ndarray
    first_pier_m: float
    last_pier_m: float

    def coords(self, xyz_campaign: np.ndarray) -> np.ndarray:
        """(N, 3) station, lateral offset and height of campaign-frame points."""
        return self.from_layout(self.to_layout.apply(np.asarray(xyz_campaign, dtype=np.float64)))

    def from_layout(self, xyz_layout: np.ndarray) -> np.ndarray:
        """(N, 3) station, lateral offset and height of layout-frame points."""
        return np.asarray(xyz_layout, dtype=np.float64) @ np.column_stack([self.axis, self.side, self.up])

    def registration_sigma(self, transform: Transform, pivot_campaign: np.ndarray) -> RegistrationSigma:
        """An epoch's registration uncertainty (its transform's σ) about a pivot in the campaign frame."""
        s, lat, _ = self.coords(np.asarray(pivot_campaign, dtype=np.float64).reshape(1, 3))[0]
        return RegistrationSigma(float(np.nan_to_num(transform.sigma_translation_m)),
                                 float(np.radians(np.nan_to_num(transform.sigma_rotation_deg))), (float(s), float(lat)))


def span_frame(layout: Layout, ids: list[str], xyz_campaign: np.ndarray, up_layout: np.ndarray) -> SpanFrame:
    """Tie the campaign frame to the layout by the targets measured in the baseline.

    Parameters
    ----------
    layout : Layout
    ids : list of str
        Targets whose campaign-frame positions are given.
    xyz_campaign : (K, 3) array
        Their positions in the campaign frame (NaN rows where not measured).
    up_layout : (3,) array
        The layout's up direction (the ``layout_up`` setting).

    Returns
    -------
    SpanFrame

    Raises
    ------
    CampaignError
        Fewer than three targets measured in the baseline.
    """
    xyz_campaign = np.asarray(xyz_campaign, dtype=np.float64)
    ok = np.all(np.isfinite(xyz_campaign), axis=1)
    if ok.sum() < 3:
        raise CampaignError("the span profile needs at least three targets measured in the baseline epoch")
    lay = np.array([layout.xyz[layout.index(i)] for i in ids])
    to_layout = fit_rigid(xyz_campaign[ok], lay[ok], source_frame="campaign", target_frame="layout")
    up = np.asarray(up_layout, dtype=np.float64)
    up = up / np.linalg.norm(up)
    axis = bridge_axis(layout, up=up)
    x_hint = np.array([1.0, 0.0, 0.0]) - up[0] * up  # the layout's x, made horizontal
    if np.linalg.norm(x_hint) > 1e-6 and axis @ x_hint < 0:
        axis = -axis
    side = np.cross(up, axis)
    refs = [k for k, g in enumerate(layout.groups) if g == "reference"]
    pts = layout.xyz[refs] if refs else layout.xyz
    st = pts @ axis
    return SpanFrame(to_layout, axis, side, up, float(st.min()), float(st.max()))


def pivot(xyz_campaign: np.ndarray, used: np.ndarray | None = None) -> np.ndarray:
    """Centroid of the tie points used by a registration (the point its translation σ refers to)."""
    xyz_campaign = np.asarray(xyz_campaign, dtype=np.float64)
    ok = np.all(np.isfinite(xyz_campaign), axis=1)
    if used is not None:
        ok &= np.asarray(used, dtype=bool)
    return xyz_campaign[ok].mean(axis=0)

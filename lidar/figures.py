"""Figures of the LiDAR pipeline (matplotlib, no GUI toolkit): reflectance maps with detections and ROIs."""
from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from common.files import atomic_output
from lidar.angles import spherical_from_xyz

if TYPE_CHECKING:
    from lidar.detection import DetectionResult
    from lidar.identification import Identification
    from lidar.reflectance_map import ReflectanceMap


def reflectance_map_figure(rmap: ReflectanceMap, *, detections: DetectionResult | None = None,
                           identification: Identification | None = None, rois: Sequence | None = None,
                           title: str = "Reflectance map", figsize: tuple[float, float] = (11, 4.8),
                           fixed_layout: bool = False) -> Any:
    """A matplotlib Figure of the map (max intensity) with angle axes, a colour bar, detections and ROIs.

    ``fixed_layout`` places the axes at fixed positions instead of running matplotlib's layout
    engine: several times faster, for drawing many maps (reports).
    """
    if fixed_layout:
        fig = Figure(figsize=figsize, dpi=110)
        ax = fig.add_axes((0.085, 0.14, 0.80, 0.77))
        cax = fig.add_axes((0.895, 0.14, 0.018, 0.77))
    else:
        fig = Figure(figsize=figsize, dpi=110, layout="constrained")
        ax = fig.add_subplot(1, 1, 1)
        cax = None
    img = np.ma.masked_invalid(rmap.max_intensity)
    extent = rmap.extent_deg

    cmap = matplotlib.colormaps["gray"].with_extremes(bad="#dfe9f5")  # light blue: no return (sky)
    im = ax.imshow(img, cmap=cmap, vmin=0, vmax=1, extent=extent, aspect="auto", interpolation="nearest")
    ax.invert_xaxis()  # azimuth grows counter-clockwise: to the left, as the scanner sees the scene
    if cax is not None:
        fig.colorbar(im, cax=cax, label="normalised intensity (max per cell)")
    else:
        fig.colorbar(im, ax=ax, label="normalised intensity (max per cell)", pad=0.01)
    ax.set_xlabel("azimuth phi [deg]")
    ax.set_ylabel("zenith angle theta [deg]")
    ax.set_title(title)

    def unwrap(phi):  # into the map's continuous azimuth range
        return rmap.phi0_deg + np.mod(np.asarray(phi) - rmap.phi0_deg, 360.0)

    if detections is not None:
        for _k, d in enumerate(detections.detections):
            ax.plot(unwrap(d.phi_deg), d.theta_deg, "o", mfc="none", mec="tab:orange", ms=9, mew=1.2)
    if identification is not None:
        for m in identification.matches:
            t, p, _ = spherical_from_xyz(np.array([m.xyz_socs]))
            colour = "tab:cyan" if m.group == "reference" else "tab:green"
            ax.annotate(m.id + (" (pred.)" if m.predicted else ""), (unwrap(p[0]), t[0]), color=colour,
                        fontsize=8, xytext=(4, -10), textcoords="offset points")
            if m.predicted:
                ax.plot(unwrap(p[0]), t[0], "x", color="tab:red", ms=8)
    if rois:
        for r in rois:
            w = r.window
            x0 = unwrap(w.phi_min_deg)
            ax.add_patch(Rectangle((x0, w.theta_min_deg), w.phi_max_deg - w.phi_min_deg,
                                   w.theta_max_deg - w.theta_min_deg, fill=False, ec="tab:red", lw=1.3,
                                   zorder=4))  # above the detection rings: a window is only a few pixels wide
    return fig


def save_figure(fig: Any, path: str | os.PathLike) -> Path:
    """Write a matplotlib Figure to ``path`` (format from the suffix) atomically; returns the path."""
    with atomic_output(path) as tmp:
        fig.savefig(tmp)
    return Path(path)

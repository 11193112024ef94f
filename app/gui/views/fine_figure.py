"""The picture of one target's fine-scan window (points by intensity, Otsu's split, the cluster kept, the centroid
and σ), drawn off the interface thread.

Drawing tens of thousands of points with matplotlib takes seconds; the job that reads the window also draws it
here, on a figure of its own with the Agg canvas (no Qt, no pyplot: safe in a worker thread), and the view only
shows the finished image.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

#: The picture's size in inches and its resolution: 1100 × 560 pixels, scaled to the view.
FIGSIZE = (11.0, 5.6)
DPI = 100


@dataclass(frozen=True, eq=False)
class FinePicture:
    """A :class:`projects.outputs.inspection.TargetInspection`, its drawn ``figure``, the figure's pixels
    (``rgba``, (H, W, 4) uint8) and the line the view prints above it (HTML)."""

    inspection: object
    figure: Figure
    rgba: np.ndarray
    text: str


def draw_inspection(ins) -> FinePicture:
    """Draw a target's fine-scan window (in the worker) and say what it shows."""
    fig = Figure(figsize=FIGSIZE, dpi=DPI, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    c = ins.centroid
    ax, hx = fig.subplots(1, 2, width_ratios=[3, 1.3])
    # angular offsets from the window centre, in millimetres at the target's range
    tc, pc = ins.roi.window.centre
    scale = np.radians(1.0) * ins.roi.range_m * 1e3
    x = (np.mod(ins.phi_deg - pc + 180.0, 360.0) - 180.0) * np.sin(np.radians(tc)) * scale
    y = -(ins.theta_deg - tc) * scale  # up in the image is up in the world (smaller zenith angle)
    sc = ax.scatter(x, y, c=ins.intensity, s=2, cmap="gray", vmin=0, vmax=1, rasterized=True)
    ax.scatter(x[ins.bright & ~ins.cluster], y[ins.bright & ~ins.cluster], s=5, c="tab:red",
               label="bright, left out", rasterized=True)
    ax.scatter(x[ins.cluster & ~ins.disc], y[ins.cluster & ~ins.disc], s=5, c="tab:orange",
               label="cluster rim, trimmed", rasterized=True)
    ax.scatter(x[ins.disc], y[ins.disc], s=3, c="tab:cyan", alpha=0.35,
               label=f"disc points ({int(ins.disc.sum())})", rasterized=True)
    if c.found:
        t, p = ins.centroid_angles()
        cx = (np.mod(p - pc + 180.0, 360.0) - 180.0) * np.sin(np.radians(tc)) * scale
        cy = -(t - tc) * scale
        sig_mm = float(np.sqrt(np.trace(c.cov))) * 1e3
        ax.plot(cx, cy, "+", color="yellow", ms=16, mew=2, label="centroid")
        # 2-sigma circle drawn 50x enlarged, so sub-millimetre sigma is visible
        ax.add_patch(Ellipse((cx, cy), 2 * 2 * sig_mm * 50, 2 * 2 * sig_mm * 50, fill=False, color="yellow",
                             ls="--", label="2σ × 50"))
    fig.colorbar(sc, ax=ax, label="point intensity", shrink=0.8, pad=0.02)
    # zoom on the target; the whole window is in the title
    d_mm = ins.diameter_m * 1e3
    zx, zy = (cx, cy) if c.found else (0.0, 0.0)
    half = 2.0 * d_mm
    ax.set_xlim(zx - half, zx + half)
    ax.set_ylim(zy - half, zy + half)
    ax.set_aspect("equal")
    ax.set_facecolor("0.12")  # the gaps between scan lines are dark, like the background
    ax.set_xlabel("across the view (mm at the target)")
    ax.set_ylabel("up (mm at the target)")
    ax.set_title(f"{ins.reflector} in {ins.epoch}: {len(ins.intensity):,} points in a "
                 f"{np.ptp(x):.0f} × {np.ptp(y):.0f} mm window\n(zoomed on the target)", fontsize=9)
    leg = ax.legend(loc="upper right", fontsize=7, framealpha=0.85)
    for handle in leg.legend_handles:  # the scatter dots readable, the centroid cross its plain size
        if hasattr(handle, "set_sizes"):
            handle.set_sizes([18])
    hx.hist(ins.intensity, bins=80, color="0.5", log=True)
    if np.isfinite(c.threshold):
        hx.axvline(c.threshold, color="tab:red", lw=1.5, label=f"Otsu {c.threshold:.3f}")
        hx.legend(fontsize=7)
    hx.set_xlabel("point intensity")
    hx.set_ylabel("points (log scale)")
    hx.set_title(f"separability {c.separability:.2f}")
    sig = np.sqrt(np.clip(np.diag(c.cov), 0, None)) * 1e3 if c.found else [np.nan] * 3
    stored = ins.stored
    text = (f"<b>{ins.reflector}</b> in epoch {ins.epoch}: "
            + (f"centroid from {c.n_points} points, σx/σy/σz {sig[0]:.3f}/{sig[1]:.3f}/{sig[2]:.3f} mm, "
               f"range {ins.roi.range_m:.2f} m" if c.found else "<b>no usable disc found</b>")
            + (f"; flags: {', '.join(c.flags)}" if c.flags else "; no flags"))
    if stored is not None and stored.found and c.found:
        text += f" (stored by processing: {np.linalg.norm(stored.xyz_socs - c.xyz_socs) * 1e3:.3f} mm away)"
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba()).copy()
    return FinePicture(ins, fig, rgba, text)

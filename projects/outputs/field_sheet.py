"""The printable field sheet of a plan: what to enter on the instrument, window by window.

Each window is given in the instrument's own angle convention (horizontal sense and zero, vertical
from the zenith or as elevation) with the instrument's resolution setting, a thumbnail of the
coarse scan's reflectance map around the target, the points expected on the target and the
seconds, and the total against the time budget.
"""
from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle
from reportlab.lib.units import mm
from reportlab.platypus import Image, Paragraph, Spacer

from lidar.plan import ScanPlan
from projects.outputs.report.flowables import esc, styles, table
from projects.outputs.report.pdf import write_landscape_pdf

THUMB_HALF_DEG = 1.5


def _thumbnail_png(preview, roi) -> bytes | None:
    """A small image of the stored reflectance map around a window (None without a map)."""
    if preview is None:
        return None

    matplotlib.use("Agg", force=False)
    rmap = preview.reflectance_map
    tc, pc = roi.window.centre
    half = max(THUMB_HALF_DEG, 0.8 * (roi.window.theta_max_deg - roi.window.theta_min_deg))
    row, col = rmap.cells_of(np.array([tc]), np.array([pc]))
    r0, c0 = int(round(row[0])), int(round(col[0]))
    k = max(3, int(half / rmap.step_deg))
    h, w = rmap.shape
    rows = np.clip(np.arange(r0 - k, r0 + k + 1), 0, h - 1)
    cols = np.mod(np.arange(c0 - k, c0 + k + 1), w) if rmap.full_circle else np.clip(np.arange(c0 - k, c0 + k + 1), 0, w - 1)
    img = rmap.max_intensity[np.ix_(rows, cols)]
    fig = Figure(figsize=(1.3, 1.3), dpi=110)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(np.nan_to_num(img, nan=0.0), cmap="gray", vmin=0, vmax=1, origin="upper", interpolation="nearest")
    wr = (roi.window.theta_max_deg - roi.window.theta_min_deg) / rmap.step_deg
    wc = (roi.window.phi_max_deg - roi.window.phi_min_deg) / rmap.step_deg
    ax.add_patch(Rectangle((k - wc / 2, k - wr / 2), wc, wr, fill=False, ec="red", lw=1.0))
    ax.set_axis_off()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def write_field_sheet(plan: ScanPlan, path: str | os.PathLike, *, campaign_name: str = "", preview: Any = None,
                      epoch_date: str = "", visit: Sequence[str] = ()) -> Path:
    """Write the field sheet of ``plan`` to a PDF (``preview``: the epoch's stored map, for thumbnails).

    ``visit``: the lines of :func:`projects.outputs.visit_overview.visit_overview` (the visit's set-ups in the order
    to work them), printed under the title when the visit has several set-ups.
    """
    ss = styles()
    p = plan.profile
    when = f" ({epoch_date})" if epoch_date and epoch_date != plan.epoch else ""
    story = [Paragraph(esc(f"Field sheet — {campaign_name or 'campaign'}, epoch {plan.epoch}{when}"),
                       ss["Heading1"]),
             Paragraph(esc(f"Scanner: {p.name}. Angles as the instrument shows them: {p.angle_convention()}. "
                            f"Resolution: {p.resolution_label}."), ss["Normal"])]
    for line in visit:
        story.append(Paragraph(esc(line), ss["Small"]))
    total, budget = plan.total_seconds, plan.budget_seconds
    over = total > budget * 1.0001
    story.append(Paragraph(esc(
        f"Total {total / 60:.1f} min for {len(plan.rois)} windows against a budget of {budget / 60:.0f} min"
        + (" — OVER BUDGET" if over else f" ({100 * total / budget:.0f} % of it)")
        + (f"; one full-dome scan at {p.preset_label(plan.dome_step_deg)} ({plan.dome_seconds / 60:.1f} min), "
           "every window is cut from it" if plan.dome_step_deg else "")
        + f". {plan.points_per_target} points planned per target."), ss["Normal"]))
    for w in plan.warnings:
        story.append(Paragraph(esc(f"⚠ {w}"), ss["Small"]))
    if plan.rois:
        first = plan.instrument_window(plan.rois[0])
        story.append(Paragraph(esc(
            f"Check before scanning: aim at {plan.rois[0].reflector}; the instrument should read about "
            f"H {0.5 * (first['h_start_deg'] + first['h_end_deg']):.3f}°, "
            f"V {0.5 * (first['v_start_deg'] + first['v_end_deg']):.3f}°. If it does not, the instrument's zero "
            "differs from the coarse scan's frame: re-import the coarse scan exported in the instrument's own frame."),
            ss["Small"]))
    story.append(Spacer(1, 3 * mm))
    header = ["#", "Map", "Target", "Horizontal from → to (°)", "Vertical from → to (°)", "Resolution",
              "Range (m)", "Incidence (°)", "Points on target", "Seconds", "Notes"]  # noqa: E501
    rows = [header]
    for k, roi in enumerate(plan.rois, start=1):
        iw = plan.instrument_window(roi)
        png = _thumbnail_png(preview, roi)
        thumb = Image(io.BytesIO(png), width=18 * mm, height=18 * mm) if png else "–"
        rows.append([str(k), thumb, f"{roi.reflector} ({roi.group})" + (" predicted" if roi.predicted else ""),
                     f"{iw['h_start_deg']:.4f} → {iw['h_end_deg']:.4f}",
                     f"{iw['v_start_deg']:.4f} → {iw['v_end_deg']:.4f}", iw["resolution"],
                     f"{roi.range_m:.2f}", f"{roi.incidence_deg:.0f}", f"{roi.expected_target_points:,}",
                     f"{roi.expected_seconds:.0f}", "; ".join(roi.notes)])
    widths = [7, 20, 24, 34, 34, 34, 14, 17, 16, 15, 52]
    story.append(table(rows, widths, ss))
    story.append(Spacer(1, 3 * mm))
    story.append(Paragraph(esc(
        "Tick each window when scanned. Import the fine scans before leaving and run "
        "'bridgesurvey check DIR --epoch L' (or Epoch ▸ Check fine scans in the application): it lists "
        "targets that came out short and writes a re-scan plan."), ss["Small"]))
    return write_landscape_pdf(story, path, title=f"Field sheet {plan.epoch}")

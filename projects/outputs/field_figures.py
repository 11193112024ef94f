"""Figures of the campaign's field model: the range walk, each visit's scale and drift (matplotlib, no GUI toolkit)."""
from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib.dates as mdates
import numpy as np
from matplotlib.figure import Figure

from lidar.systematic.adjustment import FieldModel
from lidar.systematic.range_walk import describe_basis
from projects.results.corrections import norm_sigma

#: The incidences the range-walk panel draws a curve for (cos of the angle between beam and target normal).
CURVE_COS = (1.0, 0.8, 0.6)
CURVE_COLOURS = ("#1f77b4", "#2ca02c", "#8c564b")


def _when(text: str) -> dt.datetime:
    return dt.datetime.fromisoformat(text[:19])


def range_walk_panel(ax: Any, model: FieldModel, measured: Sequence[tuple[float, float]] = ()) -> None:
    """The range bias (mm) against range, at head-on and oblique incidences, with its 2-sigma band.

    ``measured``: (range m, cos incidence) of the campaign's centroids, drawn as ticks where the data are.
    """
    rw = model.range_walk
    pts = np.asarray(measured, dtype=np.float64).reshape(-1, 2)
    lo, hi = (max(2.0, float(pts[:, 0].min()) * 0.8), float(pts[:, 0].max()) * 1.15) if len(pts) else (5.0, 80.0)
    r = np.linspace(lo, hi, 120)
    for cosi, colour in zip(CURVE_COS, CURVE_COLOURS, strict=False):
        c = np.full_like(r, cosi)
        b = rw.bias_m(r, c) * 1e3
        band = 2e3 * np.hypot(rw.sigma_m(r, c), rw.spread_m(r, c))
        ax.plot(r, b, color=colour, lw=1.2, label=f"cos i = {cosi:g}")
        ax.fill_between(r, b - band, b + band, color=colour, alpha=0.12, lw=0)
    if len(pts):
        ax.plot(pts[:, 0], rw.bias_m(pts[:, 0], pts[:, 1]) * 1e3, "k.", ms=3, label="measured targets")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_xlabel("range [m]")
    ax.set_ylabel("range bias [mm] (±2σ)")
    title = "Range walk: " + describe_basis(rw.basis)
    ax.set_title(title if len(title) < 46 else title[:44] + "…", fontsize=8)
    ax.legend(fontsize=6, frameon=False)
    ax.grid(alpha=0.3)


def _visit_points(model: FieldModel, times: Mapping[str, str]) -> list:
    return [(times[lab], model.visits[lab]) for lab in sorted(model.visits, key=lambda k: times.get(k, k))
            if lab in times]


def scale_panel(ax: Any, model: FieldModel, times: Mapping[str, str]) -> None:
    """Each visit's range scale (ppm against the baseline) with 2-sigma bars; hollow where it is not determined."""
    for when, v in _visit_points(model, times):
        determined = v.scale_determined or v.label == model.baseline
        ax.errorbar([_when(when)], [v.scale_ppm], yerr=[2 * v.scale_sigma_ppm], fmt="o", ms=3.5, capsize=2, lw=1,
                    color="#1f77b4" if determined else "0.55", mfc="#1f77b4" if determined else "white")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_ylabel("scale [ppm] (±2σ)")
    ax.set_title("Range scale of each visit", fontsize=8)
    ax.grid(alpha=0.3)


def drift_panel(ax: Any, model: FieldModel, times: Mapping[str, str]) -> None:
    """Each visit's tilt and twist rates (arcsec per hour) with 2-sigma bars; visits without drift are left out."""
    tilt, twist = [], []
    for when, v in _visit_points(model, times):
        if not v.timed:
            continue
        d, s = np.asarray(v.drift_arcsec_h, dtype=np.float64), v.drift_sigma_arcsec_h
        n, ns = norm_sigma((float(d[0]), float(d[1])), (float(s[0]), float(s[1])))
        tilt.append((_when(when), n, ns))
        twist.append((_when(when), abs(float(d[2])), float(s[2])))
    for rows, colour, name in ((tilt, "#d62728", "tilt"), (twist, "#9467bd", "twist")):
        if rows:
            x, y, e = zip(*rows, strict=False)
            ax.errorbar(list(x), y, yerr=[2 * v for v in e], fmt="o", ms=3.5, capsize=2, lw=1, color=colour,
                        label=name)
    if tilt:
        ax.legend(fontsize=6, frameon=False)
    else:
        ax.text(0.5, 0.5, "no drift found\n(or no scan times)", ha="center", va="center", transform=ax.transAxes,
                fontsize=8, color="0.4")
        ax.set_xticks([])
        ax.set_yticks([])
    ax.set_ylabel("drift [″/h] (±2σ)")
    ax.set_title("Drift of the set-up during each visit", fontsize=8)
    ax.grid(alpha=0.3)


def field_model_figure(model: FieldModel, times: Mapping[str, str], *,
                       measured: Sequence[tuple[float, float]] = (),
                       figsize: tuple[float, float] | None = None) -> Any:
    """Three panels: the range walk, each visit's scale and each visit's drift.

    ``times``: epoch label -> ISO date-time (the visits the figure places on its time axes);
    ``measured``: (range m, cos incidence) of the campaign's centroids.
    """
    fig = Figure(figsize=figsize or (10.0, 3.0), dpi=110, layout="constrained")
    axes = fig.subplots(1, 3)
    range_walk_panel(axes[0], model, measured)
    scale_panel(axes[1], model, times)
    drift_panel(axes[2], model, times)
    for ax in axes[1:]:
        if not ax.has_data():  # an empty panel keeps no time axis (it would count from 1970)
            continue
        for label in ax.get_xticklabels():
            label.set_rotation(30)
            label.set_fontsize(7)

        lo, hi = ax.get_xlim()
        if hi - lo < 2.0:  # one visit: a week either side, so that the date axis has ticks to place
            mid = 0.5 * (lo + hi)
            ax.set_xlim(mid - 7.0, mid + 7.0)
        ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d"))
        ax.xaxis.set_major_locator(mdates.AutoDateLocator(minticks=2, maxticks=6))
    for ax in axes:
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_size(8)
        ax.yaxis.label.set_size(8)
    return fig

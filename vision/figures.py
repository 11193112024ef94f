"""Figures of the camera cross-validation (matplotlib Figure objects: no pyplot state, no GUI toolkit)."""
from __future__ import annotations

import datetime as dt
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from common.series import Series
from vision.crossval import CrossValidation


def _fmt(v: float, fmt: str) -> str:
    """A statistic as text: '-' for NaN, and no minus sign on a value that rounds to zero."""
    if not np.isfinite(v):
        return "-"
    text = fmt.format(v)
    return fmt.format(0.0) if text[:1] == "-" and text.lstrip("+-").strip("0.") == "" else text


def _legend_outside(ax: Any) -> None:
    """The legend to the right of the axes, never over the data."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, frameon=False, borderaxespad=0.0)


def _dates(ns: np.ndarray):
    return np.asarray(ns, dtype="datetime64[ns]").astype("datetime64[ms]").astype(dt.datetime)


def _envelope(t_ns: np.ndarray, v: np.ndarray, bins: int = 4000):
    """Min/max per time bin, so 800,000 samples plot as a faithful band quickly."""
    if len(t_ns) <= 2 * bins:
        return t_ns, v, v
    edges = np.linspace(t_ns[0], t_ns[-1], bins + 1)
    idx = np.clip(np.searchsorted(edges, t_ns, side="right") - 1, 0, bins - 1)
    vmin = np.full(bins, np.inf)
    vmax = np.full(bins, -np.inf)
    ok = np.isfinite(v)
    np.minimum.at(vmin, idx[ok], v[ok])
    np.maximum.at(vmax, idx[ok], v[ok])
    centres = ((edges[:-1] + edges[1:]) / 2).astype(np.int64)
    empty = ~np.isfinite(vmin)
    vmin[empty] = np.nan
    vmax[empty] = np.nan
    return centres, vmin, vmax


def _pairs_with(cv: CrossValidation, attr: str):
    """The pairs whose ``attr`` is finite, and their times as datetimes."""
    p = [q for q in cv.pairs if np.isfinite(getattr(q, attr))]
    ns = np.array([np.datetime64(q.datetime.replace("+00:00", ""), "ns") for q in p], "datetime64[ns]")
    return p, _dates(ns.astype(np.int64))


def overlay_figure(cv: CrossValidation, camera: Series | None = None, *, ax: Any = None) -> Any:
    """Camera series (aligned) with the LiDAR epochs and their +-2 sigma error bars."""
    fig = None
    if ax is None:
        fig = Figure(figsize=(10, 4.2), layout="constrained")
        ax = fig.add_subplot()
    if camera is not None and len(camera):
        t, lo, hi = _envelope(camera.time_ns, camera.values + cv.offset_mm)
        ax.fill_between(_dates(t), lo, hi, color="tab:orange", alpha=0.35, lw=0, label="camera (min-max)")
        ax.plot(_dates(t), (lo + hi) / 2, color="tab:orange", lw=0.6)
    p, tt = _pairs_with(cv, "lidar_mm")
    ax.errorbar(tt, [q.lidar_mm for q in p], yerr=[2 * q.lidar_sigma_mm for q in p], fmt="o", ms=3.5,
                color="tab:blue", ecolor="tab:blue", capsize=2, lw=0.8, label="LiDAR (±2σ)")
    ax.set_ylabel("vertical displacement (mm, up)")
    head = f"{cv.series or 'camera'} vs LiDAR {cv.reflector}"
    ax.set_title(f"{head}: {cv.note}" if not cv.has_statistics else
                 f"{head}: bias {_fmt(cv.bias_mm, '{:+.2f}')} mm, RMSE {_fmt(cv.rmse_mm, '{:.2f}')} mm, "
                 f"r = {_fmt(cv.correlation, '{:.3f}')}")
    ax.grid(alpha=0.3)
    _legend_outside(ax)
    return fig or ax.figure


def difference_figure(cv: CrossValidation, *, ax: Any = None) -> Any:
    """LiDAR - camera at every pair over time, with +-2 sigma bars and the bias line."""
    fig = None
    if ax is None:
        fig = Figure(figsize=(10, 3.2), layout="constrained")
        ax = fig.add_subplot()
    p, tt = _pairs_with(cv, "difference_mm")
    ax.errorbar(tt, [q.difference_mm for q in p], yerr=[2 * q.sigma_mm for q in p], fmt="o", ms=3.5,
                color="tab:purple", capsize=2, lw=0.8)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_ylabel("LiDAR − camera (mm)")
    ax.grid(alpha=0.3)
    if not cv.has_statistics:
        ax.set_title(f"Differences ({cv.note})")
        return fig or ax.figure
    ax.axhline(cv.bias_mm, color="tab:red", lw=1.0, ls="--", label=f"bias {_fmt(cv.bias_mm, '{:+.2f}')} mm")
    ax.set_title(f"Differences ({cv.n_pairs} pairs, RMSE {_fmt(cv.rmse_mm, '{:.2f}')} mm, "
                 f"{_fmt(100 * cv.within_2sigma, '{:.0f}')} % within 2σ)")
    _legend_outside(ax)
    return fig or ax.figure


def scatter_figure(cv: CrossValidation, *, ax: Any = None) -> Any:
    """LiDAR against camera at the pairs, with the 1:1 line."""
    fig = None
    if ax is None:
        fig = Figure(figsize=(5, 5), layout="constrained")
        ax = fig.add_subplot()
    p = [q for q in cv.pairs if np.isfinite(q.difference_mm)]
    x = np.array([q.camera_mm for q in p])
    y = np.array([q.lidar_mm for q in p])
    ax.errorbar(x, y, yerr=[2 * q.lidar_sigma_mm for q in p], fmt="o", ms=3.5, color="tab:blue", capsize=2, lw=0.8)
    lo, hi = float(min(x.min(), y.min())), float(max(x.max(), y.max()))
    pad = 0.05 * (hi - lo or 1.0)
    ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], "k--", lw=0.9, label="1:1")
    ax.set_xlim(lo - pad, hi + pad)
    ax.set_ylim(lo - pad, hi + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("camera (mm, aligned)")
    ax.set_ylabel("LiDAR (mm)")
    ax.set_title(f"r = {_fmt(cv.correlation, '{:.3f}')}, slope {_fmt(cv.slope, '{:.3f}')}" if cv.has_statistics
                 else "too few pairs for statistics")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)
    return fig or ax.figure

"""Simulated output of a dual-camera installation: a 1-minute displacement series with its troubles."""
from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from common.files import atomic_output


def simulate_series(start_ns: int, end_ns: int, truth_mm: Callable[[np.ndarray], np.ndarray], *,
                    sampling_s: float = 60.0, noise_mm: float = 0.25, zero_offset_mm: float = 0.0,
                    outages: Sequence[tuple[int, int]] = (), nan_fraction: float = 0.001,
                    rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Times (int64 UTC ns) and values (mm) of a camera series following ``truth_mm(time_ns)``.

    The camera has its own zero (``zero_offset_mm`` is added), white noise ``noise_mm``, no rows
    during ``outages`` (start_ns, end_ns) and a fraction of empty readings (NaN).
    """
    rng = rng or np.random.default_rng(0)
    step = int(sampling_s * 1e9)
    t = np.arange(int(start_ns), int(end_ns) + 1, step, dtype=np.int64)
    keep = np.ones(len(t), bool)
    for a, b in outages:
        keep &= ~((t >= a) & (t < b))
    t = t[keep]
    v = np.asarray(truth_mm(t), float) + zero_offset_mm + rng.normal(0.0, noise_mm, len(t))
    v[rng.random(len(t)) < nan_fraction] = np.nan
    return t, v


def write_series_csv(path: str | os.PathLike, time_ns: np.ndarray, value_mm: np.ndarray, *,
                     utc_offset_h: int = 0, header: str = "timestamp,displacement_mm") -> Path:
    """Write a series as CSV the way camera software does: local ISO times, millimetres, empty for NaN."""
    local = (np.asarray(time_ns, np.int64) + np.int64(utc_offset_h * 3600 * 10 ** 9)).astype("datetime64[ns]")
    stamps = np.datetime_as_string(local.astype("datetime64[s]"), unit="s")
    suffix = "" if utc_offset_h is None else f"{'+' if utc_offset_h >= 0 else '-'}{abs(utc_offset_h):02d}:00"
    vals = np.char.mod("%.3f", np.nan_to_num(value_mm, nan=0.0))
    vals = np.where(np.isfinite(value_mm), vals, "")
    body = np.char.add(np.char.add(np.char.add(stamps, suffix), ","), vals)
    with atomic_output(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(f"# dual-camera displacement, midspan, exported by the camera system\n{header}\n")
            fh.write("\n".join(body.tolist()))
            fh.write("\n")
    return Path(path)

"""Cross-validation of a camera displacement series against LiDAR epochs.

Each LiDAR epoch is paired with the camera samples within +-``window_s`` of its time (their
median, count and spread). The camera series has its own zero, so it is shifted by an offset:
either so that both agree at a chosen date (``align_at``), or by the weighted least-squares
offset over all pairs. Then the differences LiDAR - camera give bias, RMSE and correlation.
"""
from __future__ import annotations

import datetime as dt
from dataclasses import asdict, dataclass
from typing import Optional, Sequence

import numpy as np

from common.errors import InputError, ProcessingError
from common.flags import FLAG_FEW_CAMERA_SAMPLES, FLAG_NO_CAMERA_DATA, FLAG_NO_LIDAR_VALUE
from vision.series import CameraSeries


@dataclass(frozen=True)
class Pair:
    """One LiDAR epoch and the camera around its time (millimetres, positive up)."""

    epoch: str
    datetime: str
    lidar_mm: float
    lidar_sigma_mm: float
    camera_mm: float              # aligned (offset applied); NaN when no camera sample in the window
    camera_raw_mm: float
    camera_sigma_mm: float
    camera_n: int
    difference_mm: float          # lidar - camera (aligned)
    sigma_mm: float               # combined standard deviation of the difference
    flags: tuple = ()


@dataclass(frozen=True)
class CrossValidation:
    """Agreement of a camera series with LiDAR epochs.

    ``bias_mm`` is the mean of LiDAR - camera, ``rmse_mm`` the root mean square of it, ``std_mm``
    its standard deviation; ``correlation`` is Pearson's r of the two series at the pairs (NaN
    with fewer than three pairs); ``within_2sigma`` the share of pairs whose difference is within
    twice its combined sigma. ``alignment`` says how the camera's zero was set.
    """

    pairs: tuple
    n_pairs: int
    bias_mm: float
    rmse_mm: float
    std_mm: float
    max_abs_mm: float
    correlation: float
    slope: float
    within_2sigma: float
    offset_mm: float
    alignment: dict
    window_s: float
    reflector: str = ""
    series: str = ""

    def to_json(self) -> dict:
        d = asdict(self)
        d["pairs"] = [asdict(p) for p in self.pairs]
        return d

    @classmethod
    def from_json(cls, d: dict) -> "CrossValidation":
        """Rebuild from :meth:`to_json` output (JSON null read back as NaN)."""
        def num(v):
            return float("nan") if v is None else v

        pairs = tuple(Pair(**{k: (tuple(v) if k == "flags" else num(v)) for k, v in p.items()})  # type: ignore[arg-type]
                      for p in d["pairs"])
        fields = {k: num(v) for k, v in d.items() if k not in ("pairs", "alignment")}
        return cls(pairs=pairs, alignment=dict(d["alignment"]), **fields)


def _iso(ns: int) -> str:
    return dt.datetime.fromtimestamp(ns / 1e9, dt.timezone.utc).isoformat()


def cross_validate(epochs: Sequence[str], time_ns: np.ndarray, lidar_mm: np.ndarray, lidar_sigma_mm: np.ndarray,
                   camera: CameraSeries, *, window_s: float = 1800.0, align_at_ns: Optional[int] = None,
                   reflector: str = "", series: str = "") -> CrossValidation:
    """Pair LiDAR epochs with the camera series, align the camera's zero and compare.

    Parameters
    ----------
    epochs : labels of the LiDAR epochs, (n,).
    time_ns : (n,) their UTC times in nanoseconds.
    lidar_mm, lidar_sigma_mm : (n,) LiDAR displacement and its standard deviation, mm, positive up.
    camera : the camera series (mm, positive up).
    window_s : half-width of the time window around each epoch, seconds (default 30 min).
    align_at_ns : align both series at the epoch nearest this time; None for least squares.
    """
    t = np.asarray(time_ns, np.int64)
    y = np.asarray(lidar_mm, float)
    sy = np.asarray(lidar_sigma_mm, float)
    if not (len(epochs) == len(t) == len(y) == len(sy)):
        raise InputError("epochs, times, displacements and sigmas must have the same length")
    if not (window_s > 0):
        raise InputError(f"the pairing window must be positive, got {window_s} s")
    ct, cv = camera.time_ns, camera.value_mm
    lo = np.searchsorted(ct, t - int(window_s * 1e9), side="left")
    hi = np.searchsorted(ct, t + int(window_s * 1e9), side="right")
    cam = np.full(len(t), np.nan)
    cam_s = np.full(len(t), np.nan)
    cam_n = np.zeros(len(t), int)
    for k, (a, b) in enumerate(zip(lo, hi)):
        v = cv[a:b]
        v = v[np.isfinite(v)]
        cam_n[k] = len(v)
        if len(v):
            med = np.median(v)
            cam[k] = med
            spread = 1.4826 * np.median(np.abs(v - med)) if len(v) > 2 else np.nan
            cam_s[k] = 1.2533 * spread / np.sqrt(len(v)) if np.isfinite(spread) else 0.0
    paired = np.isfinite(cam) & np.isfinite(y)
    if paired.sum() == 0:
        raise ProcessingError(f"no LiDAR epoch has camera samples within +-{window_s / 60:.0f} min (camera "
                              f"{_iso(ct[0]) if len(ct) else '-'} to {_iso(ct[-1]) if len(ct) else '-'}); widen the "
                              "window or check the series' time zone")
    # The baseline epoch has sigma 0 by definition (its error is inside every other epoch's sigma);
    # weighting it as exact would pin the alignment on it, so it counts like a typical epoch.
    pos = sy[np.isfinite(sy) & (sy > 0)]
    sy_w = np.where(np.isfinite(sy) & (sy > 0), sy, np.median(pos) if len(pos) else 0.0)
    s2 = sy_w ** 2 + np.where(np.isfinite(cam_s), cam_s, 0.0) ** 2
    if align_at_ns is not None:
        cand = np.nonzero(paired)[0]
        k0 = cand[np.argmin(np.abs(t[cand] - int(align_at_ns)))]
        offset = float(y[k0] - cam[k0])
        alignment = {"method": "at-date", "requested": _iso(int(align_at_ns)), "epoch": epochs[k0],
                     "epoch_datetime": _iso(int(t[k0])), "offset_mm": offset}
    else:
        w = 1.0 / np.maximum(s2[paired], 1e-6)
        offset = float(np.sum(w * (y[paired] - cam[paired])) / np.sum(w))
        alignment = {"method": "least-squares", "offset_mm": offset}
    aligned = cam + offset
    diff = y - aligned
    sig = np.sqrt(s2)
    d = diff[paired]
    n = int(paired.sum())
    if n >= 3 and np.std(y[paired]) > 0 and np.std(cam[paired]) > 0:
        corr = float(np.corrcoef(y[paired], cam[paired])[0, 1])
        slope = float(np.polyfit(cam[paired], y[paired], 1)[0])
    else:
        corr = slope = float("nan")
    within = float(np.mean(np.abs(d) <= 2 * np.maximum(sig[paired], 1e-9)))
    pairs = []
    for k in range(len(t)):
        flags = []
        if cam_n[k] == 0:
            flags.append(FLAG_NO_CAMERA_DATA)
        elif cam_n[k] < 3:
            flags.append(FLAG_FEW_CAMERA_SAMPLES)
        if not np.isfinite(y[k]):
            flags.append(FLAG_NO_LIDAR_VALUE)
        pairs.append(Pair(epoch=str(epochs[k]), datetime=_iso(int(t[k])), lidar_mm=float(y[k]),
                          lidar_sigma_mm=float(sy[k]), camera_mm=float(aligned[k]), camera_raw_mm=float(cam[k]),
                          camera_sigma_mm=float(cam_s[k]), camera_n=int(cam_n[k]), difference_mm=float(diff[k]),
                          sigma_mm=float(sig[k]), flags=tuple(flags)))
    return CrossValidation(pairs=tuple(pairs), n_pairs=n, bias_mm=float(d.mean()), rmse_mm=float(np.sqrt(np.mean(d ** 2))),
                           std_mm=float(d.std(ddof=1)) if n > 1 else float("nan"),
                           max_abs_mm=float(np.abs(d).max()), correlation=corr, slope=slope, within_2sigma=within,
                           offset_mm=offset, alignment=alignment, window_s=float(window_s), reflector=reflector,
                           series=series)

"""Cross-validation of a camera displacement series against LiDAR epochs.

Each LiDAR epoch is paired with the camera samples within +-``window_s`` of its time (their
median, count and spread). The camera series has its own zero, so it is shifted by an offset:
either so that both agree at a chosen date (``align_at``), or by the weighted least-squares
offset over all pairs. Then the differences LiDAR - camera give bias, RMSE and correlation.

Fewer than :data:`MIN_PAIRS` pairs give no statistics (NaN, and a note that says so): one pair aligned
on itself would read "RMSE 0.000 mm, 100 % within 2 sigma".

The steps are plain functions: :func:`pair_with_camera`, :func:`align_camera`, :func:`agreement`.
"""
from __future__ import annotations

import datetime as dt
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from common.arrays import median_and_sigma
from common.errors import InputError, ProcessingError
from common.flags import FLAG_FEW_CAMERA_SAMPLES, FLAG_NO_CAMERA_DATA, FLAG_NO_LIDAR_VALUE
from common.series import Series

#: Fewer paired epochs than this give no statistics: a note says so and every statistic is NaN.
MIN_PAIRS = 5


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
    its standard deviation; ``correlation`` is Pearson's r of the two series at the pairs;
    ``within_2sigma`` the share of pairs whose difference is within twice its combined sigma.
    ``alignment`` says how the camera's zero was set. With fewer than :data:`MIN_PAIRS` pairs every
    statistic is NaN and ``note`` says why.
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
    note: str = ""

    @property
    def has_statistics(self) -> bool:
        """Whether there were enough pairs for statistics."""
        return not self.note

    def statistics_text(self) -> str:
        """The statistics in one line, or why there are none (the command line and the application print it)."""
        if not self.has_statistics:
            return self.note

        def f(v: float, fmt: str) -> str:
            return "-" if not np.isfinite(v) else fmt.format(v)

        return (f"bias {f(self.bias_mm, '{:+.3f}')} mm, RMSE {f(self.rmse_mm, '{:.3f}')} mm, "
                f"std {f(self.std_mm, '{:.3f}')} mm, max |diff| {f(self.max_abs_mm, '{:.3f}')} mm, "
                f"correlation {f(self.correlation, '{:.4f}')}, {f(100 * self.within_2sigma, '{:.0f}')} % within 2 sigma")

    def to_json(self) -> dict:
        d = asdict(self)
        d["pairs"] = [asdict(p) for p in self.pairs]
        return d

    @classmethod
    def from_json(cls, d: dict) -> CrossValidation:
        """Rebuild from :meth:`to_json` output (JSON null read back as NaN).

        A summary stored by an older version from fewer than :data:`MIN_PAIRS` pairs loses its statistics.
        """
        def num(v):
            return float("nan") if v is None else v

        pairs = tuple(Pair(**{k: (tuple(v) if k == "flags" else num(v)) for k, v in p.items()})  # type: ignore[arg-type]
                      for p in d["pairs"])
        fields = {k: num(v) for k, v in d.items() if k not in ("pairs", "alignment")}
        note = too_few_pairs_note(int(fields["n_pairs"]))
        if note:
            fields.update({k: float("nan") for k in STATISTICS}, note=note)
        return cls(pairs=pairs, alignment=dict(d["alignment"]), **fields)


#: The fields of a cross-validation that are statistics of the pairs.
STATISTICS = ("bias_mm", "rmse_mm", "std_mm", "max_abs_mm", "correlation", "slope", "within_2sigma")


def _iso(ns: int) -> str:
    return dt.datetime.fromtimestamp(ns / 1e9, dt.UTC).isoformat()


@dataclass(frozen=True, eq=False)
class CameraAtEpochs:
    """The camera around each epoch: median of the samples within the window, its sigma and the sample count."""

    median_mm: np.ndarray  # (n,), NaN where no sample falls in the window
    sigma_mm: np.ndarray  # (n,), 0 with one or two samples (no spread to judge)
    count: np.ndarray  # (n,) int


def pair_with_camera(time_ns: np.ndarray, camera: Series, *, window_s: float) -> CameraAtEpochs:
    """The camera samples within ``window_s`` seconds of each epoch time (n,), as medians with a robust sigma."""
    ct, cv = camera.time_ns, camera.values
    t = np.asarray(time_ns, np.int64)
    lo = np.searchsorted(ct, t - int(window_s * 1e9), side="left")
    hi = np.searchsorted(ct, t + int(window_s * 1e9), side="right")
    cam = np.full(len(t), np.nan)
    cam_s = np.full(len(t), np.nan)
    cam_n = np.zeros(len(t), int)
    for k, (a, b) in enumerate(zip(lo, hi, strict=False)):
        v = cv[a:b]
        v = v[np.isfinite(v)]
        cam_n[k] = len(v)
        if len(v):
            med, sigma = median_and_sigma(v)
            cam[k] = med
            spread = sigma if len(v) > 2 else np.nan
            cam_s[k] = 1.2533 * spread / np.sqrt(len(v)) if np.isfinite(spread) else 0.0
    return CameraAtEpochs(cam, cam_s, cam_n)


def align_camera(epochs: Sequence[str], time_ns: np.ndarray, lidar_mm: np.ndarray, camera_mm: np.ndarray,
                 variance_mm2: np.ndarray, paired: np.ndarray, *, align_at_ns: int | None = None
                 ) -> tuple[float, dict]:
    """The offset that sets the camera's zero, and how it was found.

    At the paired epoch nearest ``align_at_ns`` (both agree there), or the weighted least-squares offset
    over every pair (weights 1 / ``variance_mm2``).
    """
    t = np.asarray(time_ns, np.int64)
    if align_at_ns is not None:
        cand = np.nonzero(paired)[0]
        k0 = cand[np.argmin(np.abs(t[cand] - int(align_at_ns)))]
        offset = float(lidar_mm[k0] - camera_mm[k0])
        return offset, {"method": "at-date", "requested": _iso(int(align_at_ns)), "epoch": epochs[k0],
                        "epoch_datetime": _iso(int(t[k0])), "offset_mm": offset}
    w = 1.0 / np.maximum(variance_mm2[paired], 1e-6)
    offset = float(np.sum(w * (lidar_mm[paired] - camera_mm[paired])) / np.sum(w))
    return offset, {"method": "least-squares", "offset_mm": offset}


@dataclass(frozen=True)
class Agreement:
    """Statistics of LiDAR - camera over the pairs (mm); every one NaN, with ``note``, below :data:`MIN_PAIRS`."""

    n_pairs: int
    bias_mm: float = float("nan")
    rmse_mm: float = float("nan")
    std_mm: float = float("nan")
    max_abs_mm: float = float("nan")
    correlation: float = float("nan")
    slope: float = float("nan")
    within_2sigma: float = float("nan")
    note: str = ""


def too_few_pairs_note(n_pairs: int) -> str:
    """Why a cross-validation of ``n_pairs`` gives no statistics ('' from :data:`MIN_PAIRS` on).

    >>> too_few_pairs_note(1)
    'only 1 pair: too few for statistics (5 needed)'
    """
    if n_pairs >= MIN_PAIRS:
        return ""
    return f"only {n_pairs} pair{'s' if n_pairs != 1 else ''}: too few for statistics ({MIN_PAIRS} needed)"


def agreement(lidar_mm: np.ndarray, camera_mm: np.ndarray, difference_mm: np.ndarray, sigma_mm: np.ndarray,
              paired: np.ndarray) -> Agreement:
    """Bias, RMSE, spread, correlation and the share within 2 sigma of the paired differences (mm).

    Fewer than :data:`MIN_PAIRS` pairs give no statistics: one or two pairs, one of them the alignment's own,
    agree by construction and would read as a perfect match.
    """
    n = int(paired.sum())
    note = too_few_pairs_note(n)
    if note:
        return Agreement(n, note=note)
    d = difference_mm[paired]
    y, cam = lidar_mm[paired], camera_mm[paired]
    if np.std(y) > 0 and np.std(cam) > 0:
        corr = float(np.corrcoef(y, cam)[0, 1])
        slope = float(np.polyfit(cam, y, 1)[0])
    else:
        corr = slope = float("nan")
    return Agreement(n, bias_mm=float(d.mean()), rmse_mm=float(np.sqrt(np.mean(d ** 2))), std_mm=float(d.std(ddof=1)),
                     max_abs_mm=float(np.abs(d).max()), correlation=corr, slope=slope,
                     within_2sigma=float(np.mean(np.abs(d) <= 2 * np.maximum(sigma_mm[paired], 1e-9))))


def _pair_flags(camera_n: int, lidar_mm: float) -> tuple[str, ...]:
    flags = []
    if camera_n == 0:
        flags.append(FLAG_NO_CAMERA_DATA)
    elif camera_n < 3:
        flags.append(FLAG_FEW_CAMERA_SAMPLES)
    if not np.isfinite(lidar_mm):
        flags.append(FLAG_NO_LIDAR_VALUE)
    return tuple(flags)


def cross_validate(epochs: Sequence[str], time_ns: np.ndarray, lidar_mm: np.ndarray, lidar_sigma_mm: np.ndarray,
                   camera: Series, *, window_s: float = 1800.0, align_at_ns: int | None = None,
                   reflector: str = "", series: str = "") -> CrossValidation:
    """Pair LiDAR epochs with the camera series, align the camera's zero and compare.

    Parameters
    ----------
    epochs : sequence of str, (n,)
        Labels of the LiDAR epochs.
    time_ns : ndarray of int64, shape (n,)
        Their UTC times in nanoseconds.
    lidar_mm, lidar_sigma_mm : ndarray, shape (n,)
        LiDAR displacement and its standard deviation, mm, positive up.
    camera : Series
        The camera series (mm, positive up).
    window_s : float
        Half-width of the time window around each epoch, seconds (default 30 min).
    align_at_ns : int, optional
        Align both series at the epoch nearest this time; None for least squares.
    reflector, series : str
        The reflector and the series' name, recorded in the result.

    Returns
    -------
    CrossValidation
        The pairs and the statistics. With fewer than :data:`MIN_PAIRS` pairs the statistics are NaN and
        ``note`` says why.
    """
    t = np.asarray(time_ns, np.int64)
    y = np.asarray(lidar_mm, float)
    sy = np.asarray(lidar_sigma_mm, float)
    if not (len(epochs) == len(t) == len(y) == len(sy)):
        raise InputError("epochs, times, displacements and sigmas must have the same length")
    if not (window_s > 0):
        raise InputError(f"the pairing window must be positive, got {window_s} s")
    at = pair_with_camera(t, camera, window_s=window_s)
    paired = np.isfinite(at.median_mm) & np.isfinite(y)
    if paired.sum() == 0:
        ct = camera.time_ns
        raise ProcessingError(f"no LiDAR epoch has camera samples within +-{window_s / 60:.0f} min (camera "
                              f"{_iso(ct[0]) if len(ct) else '-'} to {_iso(ct[-1]) if len(ct) else '-'}); widen the "
                              "window or check the series' time zone")
    # The baseline epoch has sigma 0 by definition (its error is inside every other epoch's sigma);
    # weighting it as exact would pin the alignment on it, so it counts like a typical epoch.
    pos = sy[np.isfinite(sy) & (sy > 0)]
    sy_w = np.where(np.isfinite(sy) & (sy > 0), sy, np.median(pos) if len(pos) else 0.0)
    s2 = sy_w ** 2 + np.where(np.isfinite(at.sigma_mm), at.sigma_mm, 0.0) ** 2
    offset, alignment = align_camera(epochs, t, y, at.median_mm, s2, paired, align_at_ns=align_at_ns)
    aligned = at.median_mm + offset
    diff = y - aligned
    sig = np.sqrt(s2)
    stats = agreement(y, at.median_mm, diff, sig, paired)
    pairs = tuple(Pair(epoch=str(epochs[k]), datetime=_iso(int(t[k])), lidar_mm=float(y[k]),
                       lidar_sigma_mm=float(sy[k]), camera_mm=float(aligned[k]), camera_raw_mm=float(at.median_mm[k]),
                       camera_sigma_mm=float(at.sigma_mm[k]), camera_n=int(at.count[k]), difference_mm=float(diff[k]),
                       sigma_mm=float(sig[k]), flags=_pair_flags(int(at.count[k]), float(y[k])))
                  for k in range(len(t)))
    return CrossValidation(pairs=pairs, n_pairs=stats.n_pairs, bias_mm=stats.bias_mm, rmse_mm=stats.rmse_mm,
                           std_mm=stats.std_mm, max_abs_mm=stats.max_abs_mm, correlation=stats.correlation,
                           slope=stats.slope, within_2sigma=stats.within_2sigma, offset_mm=offset,
                           alignment=alignment, window_s=float(window_s), reflector=reflector, series=series,
                           note=stats.note)

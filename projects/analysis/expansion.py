"""The deck's movement along the span against temperature: each target's expansion coefficient.

A deck on a fixed and a free bearing slides along the span with its temperature, the farther from the fixed
bearing the more (a 40 m concrete deck moves its free end about 0.5 mm per °C). Each deck target's
along-span movement (``along_mm``, positive away from the first pier; see
:mod:`lidar.systematic.budget`) is fitted by weighted least squares as ``a + k T`` over the epochs, ``T``
the air or structure temperature at each scan. A bearing that seizes shows as a change of ``k``: the
coefficient of the earlier half of the epochs is compared with the later half's, and a difference beyond
3 sigma is said in a note.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from projects.analysis.models import wls

#: Fewest epochs with an along-span value and a temperature for a coefficient.
MIN_EPOCHS = 3
#: Fewest epochs in each half for the seized-bearing comparison.
MIN_HALF = 3


@dataclass(frozen=True)
class AlongFit:
    """One target's along-span expansion coefficient (mm per °C) with its sigma, and a note."""

    reflector: str
    epochs: int
    mm_per_degC: float | None
    sigma: float | None
    early_late: tuple[float, float, float, float] | None  # (k early, sigma, k late, sigma)
    note: str = ""
    points: tuple[tuple[float, float, float], ...] = ()  # (temperature °C, along mm, sigma mm) of the epochs used

    def to_json(self) -> dict:
        def r(v: float | None, nd: int = 4) -> float | None:
            return None if v is None or not math.isfinite(v) else round(float(v), nd)
        return {"along_epochs": self.epochs, "along_mm_per_degC": r(self.mm_per_degC),
                "along_sigma": r(self.sigma),
                "along_early_late_mm_per_degC": None if self.early_late is None else [r(v) for v in self.early_late],
                "along_note": self.note, "along_points": [[r(v, 3) for v in p] for p in self.points]}


def _slope(temp: np.ndarray, along: np.ndarray, sigma: np.ndarray) -> tuple[float, float]:
    """Weighted least-squares slope of ``along`` on ``temp`` and its sigma (scaled by the fit when it is worse)."""
    w = 1.0 / np.maximum(sigma, 1e-6) ** 2
    x = np.column_stack([np.ones_like(temp), temp])
    if np.linalg.cond(x.T @ (w[:, None] * x)) > 1e12:
        return math.nan, math.nan
    beta, cov, chi2, _, _ = wls(x, along, w)
    dof = len(temp) - 2
    s2 = chi2 / dof if dof > 0 else 1.0
    return float(beta[1]), float(math.sqrt(cov[1, 1] * max(1.0, s2)))


def fit_along(reflector: str, temp_c: npt.ArrayLike, along_mm: npt.ArrayLike, sigma_mm: npt.ArrayLike) -> AlongFit:
    """The expansion coefficient of one target from its epochs (temperatures °C, movements and sigmas mm).

    Epochs without a finite value, sigma or temperature are left out; fewer than :data:`MIN_EPOCHS`, or
    temperatures within 1 °C of each other, give no coefficient (with the reason in the note).
    """
    t, a, s = (np.asarray(v, dtype=np.float64) for v in (temp_c, along_mm, sigma_mm))
    ok = np.isfinite(t) & np.isfinite(a) & np.isfinite(s) & (s > 0)
    t, a, s = t[ok], a[ok], s[ok]
    if t.size < MIN_EPOCHS:
        return AlongFit(reflector, int(t.size), None, None, None,
                        f"{t.size} epochs with an along-span value and a temperature: {MIN_EPOCHS} needed")
    if np.ptp(t) < 1.0:
        return AlongFit(reflector, int(t.size), None, None, None,
                        f"the scans' temperatures span {np.ptp(t):.1f} °C: too little to tell an expansion")
    k, sk = _slope(t, a, s)
    early_late, note = None, ""
    if t.size >= 2 * MIN_HALF:
        half = t.size // 2
        k1, s1 = _slope(t[:half], a[:half], s[:half])
        k2, s2 = _slope(t[half:], a[half:], s[half:])
        if all(map(math.isfinite, (k1, s1, k2, s2))):
            early_late = (k1, s1, k2, s2)
            if abs(k2 - k1) > 3.0 * math.hypot(s1, s2):
                note = (f"the along-span coefficient changed from {k1:+.3f} ± {s1:.3f} to {k2:+.3f} ± {s2:.3f} mm/°C "
                        "between the earlier and the later epochs: a bearing that stops sliding shows so")
    points = tuple((float(x), float(y), float(z)) for x, y, z in zip(t, a, s, strict=False))
    return AlongFit(reflector, int(t.size), k, sk, early_late, note, points)


def temperatures_at(times_days: np.ndarray, series: tuple[np.ndarray, np.ndarray] | None, *,
                    half_window_days: float = 1.0 / 24.0) -> np.ndarray:
    """The mean temperature within ``half_window_days`` of each time (NaN where the series has none)."""
    out = np.full(len(times_days), np.nan)
    if series is None:
        return out
    st, sv = (np.asarray(v, dtype=np.float64) for v in series)
    for i, t in enumerate(times_days):
        near = (np.abs(st - t) <= half_window_days) & np.isfinite(sv)
        if near.any():
            out[i] = float(np.mean(sv[near]))
    return out

"""One target's displacement history explained by a linear model, fitted by weighted least squares.

    d(t) = c + b (T_eff(t) - T_ref) + sum_e H(t - t_e) [s_e + k_e f(t - t_e)] + r t  (+ annual terms)

* ``T_eff`` is the temperature averaged over a window ending a lag before the epoch; the window and lag
  are chosen by Akaike's information criterion (AICc), as is the creep time parameter and whether the
  trend ``r`` or, without any temperature, an annual sinusoid belongs in the model.
* ``f`` is a creep-time law with final value 1: the ACI 209 shape ``tau^0.6 / (d + tau^0.6)`` or an
  exponential approach ``1 - exp(-tau / tc)``, the law and its time parameter chosen by AICc and the
  event figures averaged over the laws with Akaike weights (the choice is uncertain too). An event's
  immediate step is ``s_e`` and the creep that follows tends to ``k_e``. The creep coefficient reported
  is the creep developed by the last epoch over the step (as the dissertation's 8 mm / 6.3 mm = 1.3);
  ``k_e / s_e``, the law's final value, is an extrapolation and given apart.
* Sigmas come from the weighted fit's covariance scaled by the reduced chi-square when that exceeds 1
  (the measurement sigmas do not hold what the model leaves out: sun, traffic, wind).

An event with fewer than two epochs before or after it, or a creep with fewer than three after, is
reported as not determinable, never as a number. A creep coefficient within 2 sigma of zero, or a
negative one (the target moved back after the step: recovery), carries a note saying so.

The pieces: :func:`design_matrix` builds the columns of a model (:class:`Term`), :func:`search_models`
fits every candidate (:class:`ModelSpec`) and returns the frozen :class:`Candidate` fits,
:func:`akaike_average` combines a quantity over them, and :class:`Predictor` evaluates the chosen model
at any time (the projection); :func:`fit_target` ties them together.
"""
from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import stats

from common.errors import InputError

CREEP_PSI = 0.6
CREEP_D_DAYS = tuple(float(v) for v in np.round(np.geomspace(3.0, 200.0, 19), 1))
CREEP_EXP_DAYS = tuple(float(v) for v in np.round(np.geomspace(5.0, 300.0, 19), 1))
#: A creep-time law: ``("aci", d)`` or ``("exp", tc)``, its time parameter in days.
CreepLaw = tuple[str, float]
#: Creep-time laws the fit chooses among (AICc) and averages over: the ACI 209 shape for several time
#: parameters, and an exponential approach 1 - exp(-t / tc) (a hyperbolic-like law with a different start).
CREEP_LAWS: tuple[CreepLaw, ...] = tuple(("aci", d) for d in CREEP_D_DAYS) + tuple(("exp", tc) for tc in CREEP_EXP_DAYS)
WINDOWS_H = (1.0, 3.0, 6.0, 12.0, 24.0, 48.0, 168.0)
LAGS_H = (0.0, 3.0, 6.0)
YEAR_D = 365.25


def creep_shape(tau_days: npt.ArrayLike, law: CreepLaw | float) -> np.ndarray:
    """The creep developed ``tau_days`` after loading as a share of the final creep (0 to 1).

    ``law`` is ``("aci", d)``: ``tau^0.6 / (d + tau^0.6)`` (ACI 209), ``("exp", tc)``: ``1 - exp(-tau / tc)``,
    or a bare number ``d`` for the ACI shape.
    """
    kind, p = ("aci", float(law)) if not isinstance(law, tuple) else law
    tau = np.clip(np.asarray(tau_days, dtype=np.float64), 0.0, None)
    if kind == "exp":
        return 1.0 - np.exp(-tau / p)
    tau = tau ** CREEP_PSI
    return tau / (p + tau)


@dataclass(frozen=True)
class Event:
    """An event as the fit sees it: its time in days from the baseline, label, kind and date."""

    t_days: float
    label: str
    kind: str = "construction"
    date: str = ""


@dataclass(frozen=True)
class EventFit:
    """What the fit found for one event: its step and creep (mm, with sigma) and the creep coefficients."""

    label: str
    date: str
    kind: str
    step_mm: float = float("nan")
    step_sigma_mm: float = float("nan")
    creep_mm: float = float("nan")  # developed by the last epoch
    creep_sigma_mm: float = float("nan")
    creep_final_mm: float = float("nan")  # the fitted law's final value (an extrapolation)
    creep_final_sigma_mm: float = float("nan")
    creep_coefficient: float = float("nan")  # developed creep / immediate step, as the dissertation reports it
    creep_coefficient_sigma: float = float("nan")
    creep_coefficient_final: float = float("nan")  # final creep / step: extrapolated, less certain
    creep_coefficient_final_sigma: float = float("nan")
    note: str = ""
    t_days: float = float("nan")  # the event's time on the fit's axis


@dataclass(frozen=True)
class Term:
    """One column of a model's design matrix.

    ``kind`` is ``offset``, ``thermal`` (the effective temperature minus the reference), ``step`` and
    ``creep`` (of ``event``), ``trend`` (per year), ``annual_sin`` or ``annual_cos``.
    """

    kind: str
    event: Event | None = None


@dataclass(frozen=True, eq=False)
class TemperatureWindow:
    """The temperature averaged over ``window_h`` hours ending ``lag_h`` before each epoch, (n,) degC (NaN: none)."""

    window_h: float
    lag_h: float
    at_epochs: np.ndarray


@dataclass(frozen=True, eq=False)
class ModelSpec:
    """One candidate model: its temperature window (or none), creep law, trend and annual terms."""

    temperature: TemperatureWindow | None
    reference_temperature: float | None
    events: tuple[tuple[Event, bool], ...]  # (event, whether its creep is determinable)
    creep_law: CreepLaw | None = None
    trend: bool = False
    annual: bool = False

    def terms(self) -> tuple[Term, ...]:
        """The model's columns, in design-matrix order."""
        out = [Term("offset")]
        if self.temperature is not None:
            out.append(Term("thermal"))
        for e, creep in self.events:
            out.append(Term("step", e))
            if creep and self.creep_law is not None:
                out.append(Term("creep", e))
        if self.trend:
            out.append(Term("trend"))
        if self.annual:
            out += [Term("annual_sin"), Term("annual_cos")]
        return tuple(out)

    def temperature_deviation(self) -> np.ndarray | None:
        """(n,) effective temperature minus the reference at the epochs (0 where unknown), or None."""
        if self.temperature is None or self.reference_temperature is None:
            return None
        return np.nan_to_num(self.temperature.at_epochs - self.reference_temperature)


def design_matrix(t_days: np.ndarray, terms: Sequence[Term], *, creep_law: CreepLaw | None = None,
                  temperature_deviation: np.ndarray | None = None) -> np.ndarray:
    """The (n, p) design matrix of ``terms`` at times ``t_days`` (n,).

    ``temperature_deviation`` (n,) fills the thermal column; None gives 0 there (the model at the reference
    temperature, as a projection wants it). ``creep_law`` shapes the creep columns.
    """
    t = np.asarray(t_days, dtype=np.float64)
    cols = []
    for term in terms:
        if term.kind == "offset":
            cols.append(np.ones_like(t))
        elif term.kind == "thermal":
            cols.append(np.zeros_like(t) if temperature_deviation is None else temperature_deviation)
        elif term.kind == "trend":
            cols.append(t / YEAR_D)
        elif term.kind == "annual_sin":
            cols.append(np.sin(2 * np.pi * t / YEAR_D))
        elif term.kind == "annual_cos":
            cols.append(np.cos(2 * np.pi * t / YEAR_D))
        elif term.event is not None and term.kind == "step":
            cols.append((t >= term.event.t_days).astype(float))
        elif term.event is not None and term.kind == "creep" and creep_law is not None:
            cols.append((t >= term.event.t_days).astype(float) * creep_shape(t - term.event.t_days, creep_law))
        else:
            raise ValueError(f"cannot build a column for {term}")
    return np.column_stack(cols)


@dataclass(frozen=True, eq=False)
class Candidate:
    """One fitted candidate model (weighted least squares over the epochs in ``use``)."""

    spec: ModelSpec
    terms: tuple[Term, ...]
    use: np.ndarray  # (n,) bool, the epochs the fit used
    coef: np.ndarray  # (p,)
    cov: np.ndarray  # (p, p), from the measurement sigmas alone
    chi2: float
    aicc: float
    resid: np.ndarray  # (m,) at the used epochs, mm

    @property
    def dof(self) -> int:
        """Degrees of freedom: used epochs minus parameters."""
        return int(self.use.sum()) - len(self.coef)

    @property
    def reduced_chi2(self) -> float:
        """Chi-square per degree of freedom (at least one degree)."""
        return self.chi2 / max(self.dof, 1)

    @property
    def scaled_cov(self) -> np.ndarray:
        """The covariance scaled by the reduced chi-square when that exceeds 1."""
        red = self.reduced_chi2
        return self.cov * (red if red > 1 else 1.0)

    def index(self, term: Term) -> int | None:
        """The column of ``term``, or None when the model lacks it."""
        return self.terms.index(term) if term in self.terms else None

    def estimate(self, term: Term) -> tuple[float, float] | None:
        """(value, variance) of one coefficient, the variance scaled; None when the model lacks it."""
        i = self.index(term)
        return None if i is None else (float(self.coef[i]), float(self.scaled_cov[i, i]))


def wls(X: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float, np.ndarray]:
    """Weighted least squares of ``y`` on the columns of ``X``: (coefficients, covariance, chi2, AICc, residuals)."""
    sw = np.sqrt(w)
    A = X * sw[:, None]
    b = y * sw
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    resid = y - X @ coef
    chi2 = float(np.sum(w * resid ** 2))
    n, p = X.shape
    try:
        cov = np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(A.T @ A)
    aicc = chi2 + 2 * p + (2 * p * (p + 1)) / max(n - p - 1, 1)
    return coef, cov, chi2, aicc, resid


def fit_candidate(t: np.ndarray, d: np.ndarray, w: np.ndarray, spec: ModelSpec) -> Candidate | None:
    """Fit one candidate model; None when it has too few epochs or dependent columns."""
    use = np.ones(len(t), bool) if spec.temperature is None else np.isfinite(spec.temperature.at_epochs)
    terms = spec.terms()
    X = design_matrix(t, terms, creep_law=spec.creep_law, temperature_deviation=spec.temperature_deviation())[use]
    if X.shape[0] <= X.shape[1] + 1 or np.linalg.matrix_rank(X) < X.shape[1]:
        return None
    coef, cov, chi2, aicc, resid = wls(X, d[use], w[use])
    return Candidate(spec, terms, use, coef, cov, chi2, aicc, resid)


def model_specs(t: np.ndarray, windows: Sequence[TemperatureWindow | None], events: Sequence[tuple[Event, bool]],
                *, reference_temperature: float | None = None) -> Iterable[ModelSpec]:
    """Every candidate model, in search order: temperature window, creep law, trend, annual terms."""
    span = float(t.max() - t.min())
    laws: Sequence[CreepLaw | None] = CREEP_LAWS if any(c for _, c in events) else (None,)
    for tw in windows:
        t_ref = None
        if tw is not None:
            use = np.isfinite(tw.at_epochs)
            t_ref = float(np.median(tw.at_epochs[use])) if reference_temperature is None else float(reference_temperature)
        for law in laws:
            for trend in (False, True):
                for annual in ((False, True) if tw is None and span >= 300 else (False,)):
                    yield ModelSpec(tw, t_ref, tuple(events), law, trend, annual)


def search_models(t: np.ndarray, d: np.ndarray, w: np.ndarray, specs: Iterable[ModelSpec]
                  ) -> tuple[Candidate | None, tuple[Candidate, ...]]:
    """The candidate with the lowest AICc, and the best candidate of each creep law (first seen first).

    Ties keep the earlier candidate.
    """
    best: Candidate | None = None
    per_law: dict[CreepLaw | None, Candidate] = {}
    for spec in specs:
        cand = fit_candidate(t, d, w, spec)
        if cand is None:
            continue
        if best is None or cand.aicc < best.aicc - 1e-9:
            best = cand
        law = spec.creep_law
        if law not in per_law or cand.aicc < per_law[law].aicc - 1e-9:
            per_law[law] = cand
    return best, tuple(per_law.values())


def akaike_weights(models: Sequence[Candidate]) -> np.ndarray:
    """Akaike weights of the models (summing to 1)."""
    a_min = min(m.aicc for m in models)
    wts = np.array([math.exp(-0.5 * (m.aicc - a_min)) for m in models])
    return wts / wts.sum()


def akaike_average(weights: np.ndarray, values: Sequence[tuple[float, float] | None]) -> tuple[float, float]:
    """Akaike-weighted mean and sigma of per-model (value, variance) pairs.

    The spread between the models is added to the variance; NaN when a model lacks the quantity.
    """
    if any(v is None for v in values):
        return float("nan"), float("nan")
    vals = [v for v in values if v is not None]
    mean = float(sum(w_ * v[0] for w_, v in zip(weights, vals, strict=False)))
    var = float(sum(w_ * (v[1] + (v[0] - mean) ** 2) for w_, v in zip(weights, vals, strict=False)))
    return mean, math.sqrt(var)


@dataclass(frozen=True, eq=False)
class Predictor:
    """The chosen model at any time, at the reference temperature: (value, sigma) in mm for days (k,)."""

    terms: tuple[Term, ...]
    coef: np.ndarray
    cov: np.ndarray  # scaled by the reduced chi-square
    creep_law: CreepLaw | None

    def __call__(self, t_days: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        J = design_matrix(t_days, self.terms, creep_law=self.creep_law)
        return J @ self.coef, np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", J, self.cov, J), 0.0))


@dataclass(frozen=True)
class TargetFit:
    """Everything the model says about one target (mm, days, degrees Celsius)."""

    n_epochs: int
    thermal_mm_per_degC: float = float("nan")
    thermal_sigma: float = float("nan")
    thermal_p_value: float = float("nan")
    temperature_window_h: float | None = None
    temperature_lag_h: float | None = None
    reference_temperature_degC: float | None = None
    events: tuple[EventFit, ...] = ()
    trend_mm_per_year: float = float("nan")
    trend_sigma: float = float("nan")
    seasonal_amplitude_mm: float = float("nan")
    creep_d_days: float | None = None
    creep_law: str | None = None
    scale: float = 1.0  # sqrt of the reduced chi-square applied to the sigmas
    rms_residual_mm: float = float("nan")
    corrected_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    corrected_sigma_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    temperature_at_epochs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    epoch_days: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_sigma_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    notes: tuple[str, ...] = ()
    predictor: Predictor | None = None  # the model at the reference temperature, for projections

    def predict(self, t_days: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(value, sigma) in mm of the model at the reference temperature at ``t_days`` (k,)."""
        if self.predictor is None:
            raise InputError("this target's model could not be fitted")
        return self.predictor(np.atleast_1d(np.asarray(t_days, dtype=np.float64)))


def effective_temperature(t_days: np.ndarray, temp_t_days: np.ndarray, temp: np.ndarray, window_h: float,
                          lag_h: float) -> np.ndarray:
    """Mean temperature over ``[t - lag - window, t - lag]`` for each epoch (NaN where no sample falls)."""
    ok = np.isfinite(temp)
    tt, vv = temp_t_days[ok], temp[ok]
    c = np.concatenate([[0.0], np.cumsum(vv)])
    hi = np.searchsorted(tt, t_days - lag_h / 24.0, side="right")
    lo = np.searchsorted(tt, t_days - (lag_h + window_h) / 24.0, side="left")
    n = hi - lo
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (c[hi] - c[lo]) / n
    return np.where(n > 0, out, np.nan)


def temperature_windows(t: np.ndarray, temperature: tuple[np.ndarray, np.ndarray] | None, notes: list[str]
                        ) -> list[TemperatureWindow | None]:
    """The averaging windows and lags that cover the most epochs (at least 4), or ``[None]`` (no thermal term).

    Appends to ``notes`` what the fit cannot use.
    """
    if temperature is None:
        return [None]
    tt, tv = (np.asarray(a, dtype=np.float64) for a in temperature)
    order = np.argsort(tt)
    tt, tv = tt[order], tv[order]
    cands = [TemperatureWindow(wh, lh, effective_temperature(t, tt, tv, wh, lh)) for wh in WINDOWS_H for lh in LAGS_H]
    cover = [int(np.sum(np.isfinite(c.at_epochs))) for c in cands]
    best_cover = max(cover)
    if best_cover < len(t):
        notes.append(f"the temperature series covers {best_cover} of {len(t)} epochs; the thermal fit uses those")
    if best_cover >= 4:
        return [c for c, k in zip(cands, cover, strict=False) if k == best_cover]
    notes.append("the temperature series does not overlap the epochs: no thermal fit")
    return [None]


def _events_to_fit(t: np.ndarray, events: Sequence[Event]) -> tuple[list[tuple[Event, bool]], list[EventFit]]:
    """(event, creep determinable) for the events the epochs can determine, and EventFits for the others."""
    fit, left_out = [], []
    for e in sorted(events, key=lambda e: e.t_days):
        before, after = int(np.sum(t < e.t_days)), int(np.sum(t >= e.t_days))
        if before < 2 or after < 2:
            left_out.append(EventFit(e.label, e.date, e.kind, t_days=e.t_days,
                                     note=f"not determinable: {before} epoch(s) before and {after} after (2 each needed)"))
        else:
            fit.append((e, after >= 3))
    return fit, left_out


def _event_estimates(m: Candidate, e: Event, t_last: float) -> dict[str, tuple[float, float]]:
    """One model's (value, variance) of the event's step, final creep, developed creep and creep coefficients."""
    cv = m.scaled_cov
    i_s = m.index(Term("step", e))
    assert i_s is not None  # every candidate has a step column for every event it fits
    step = float(m.coef[i_s])
    out = {"s": (step, float(cv[i_s, i_s]))}
    i_k = m.index(Term("creep", e))
    if i_k is not None and m.spec.creep_law is not None:
        k = float(m.coef[i_k])
        f_last = float(creep_shape(t_last - e.t_days, m.spec.creep_law))
        c2 = cv[np.ix_([i_s, i_k], [i_s, i_k])]
        out["k"] = (k, float(cv[i_k, i_k]))
        # developed by the last epoch (what the dissertation reports) and the law's final value
        for key, kk in (("phi", k * f_last), ("phi_final", k)):
            scale_k = f_last if key == "phi" else 1.0
            g = np.array([-kk / step ** 2, scale_k / step]) if step != 0 else np.array([np.nan, np.nan])
            out[key] = (kk / step if step != 0 else float("nan"), float(max(g @ c2 @ g, 0.0)))
        out["creep_now"] = (k * f_last, float(f_last ** 2 * cv[i_k, i_k]))
    return out


def creep_note(coefficient: float, sigma: float) -> str:
    """What a creep coefficient means when it is not an ordinary creep: negative, or within 2 sigma of zero.

    >>> creep_note(1.3, 0.2)
    ''
    >>> creep_note(-0.6, 0.1)
    'negative creep coefficient: the target moved back after the step (recovery), not creep in its direction'
    >>> creep_note(-0.1, 0.2)
    'negative creep coefficient, but within 2 sigma of zero: not determinable from these epochs'
    """
    if not (math.isfinite(coefficient) and math.isfinite(sigma)):
        return ""
    if abs(coefficient) <= 2 * sigma:
        return ("negative creep coefficient, but within" if coefficient < 0 else "creep coefficient within") + \
            " 2 sigma of zero: not determinable from these epochs"
    if coefficient < 0:
        return "negative creep coefficient: the target moved back after the step (recovery), not creep in its direction"
    return ""


def _event_fit(e: Event, models: Sequence[Candidate], weights: np.ndarray, best: Candidate, t_last: float) -> EventFit:
    """The Akaike-averaged step, creep and creep coefficients of one event, with a note on what is not determinable."""
    per_model = [_event_estimates(m, e, t_last) for m in models]

    def avg(key: str) -> tuple[float, float]:
        return akaike_average(weights, [p.get(key) for p in per_model])

    step, s_step = avg("s")
    if best.index(Term("creep", e)) is None:
        return EventFit(e.label, e.date, e.kind, step_mm=step, step_sigma_mm=s_step, t_days=e.t_days,
                        note="creep not determinable: fewer than 3 epochs after the event")
    (k, s_k), (phi, s_phi), (phi_f, s_phi_f), (now, s_now) = avg("k"), avg("phi"), avg("phi_final"), avg("creep_now")
    if not abs(step) > 2 * s_step:
        phi = s_phi = phi_f = s_phi_f = float("nan")
        note = "the step is within 2 sigma of zero: its creep coefficient is not determinable"
    else:
        note = creep_note(phi, s_phi)
    return EventFit(e.label, e.date, e.kind, step_mm=step, step_sigma_mm=s_step, creep_mm=now, creep_sigma_mm=s_now,
                    creep_final_mm=k, creep_final_sigma_mm=s_k, creep_coefficient=phi, creep_coefficient_sigma=s_phi,
                    creep_coefficient_final=phi_f, creep_coefficient_final_sigma=s_phi_f, note=note, t_days=e.t_days)


def _seasonal_temperature_amplitude(temperature: tuple[np.ndarray, np.ndarray]) -> float:
    """Amplitude of an annual sinusoid fitted to the temperature series, degC."""
    tt, tv = (np.asarray(a, dtype=np.float64) for a in temperature)
    okk = np.isfinite(tv)
    A = np.column_stack([np.ones(okk.sum()), np.sin(2 * np.pi * tt[okk] / YEAR_D),
                         np.cos(2 * np.pi * tt[okk] / YEAR_D)])
    ca, *_ = np.linalg.lstsq(A, tv[okk], rcond=None)
    return math.hypot(ca[1], ca[2])


def _thermal_fit(best: Candidate, models: Sequence[Candidate], weights: np.ndarray, d: np.ndarray, s: np.ndarray,
                 scale: float, temperature: tuple[np.ndarray, np.ndarray] | None, span: float) -> dict[str, Any]:
    """The TargetFit fields of the thermal term (Akaike-averaged) and the temperature-corrected series."""
    tw, t_ref = best.spec.temperature, best.spec.reference_temperature
    if tw is None or t_ref is None:
        return {"corrected_mm": d, "corrected_sigma_mm": s * scale}

    b, sb = akaike_average(weights, [m.estimate(Term("thermal")) for m in models])
    dT = np.nan_to_num(tw.at_epochs - t_ref)
    out: dict[str, Any] = dict(thermal_mm_per_degC=b, thermal_sigma=sb,
               thermal_p_value=float(2 * stats.t.sf(abs(b) / sb, max(best.dof, 1))) if sb > 0 else float("nan"),
               temperature_window_h=tw.window_h, temperature_lag_h=tw.lag_h, reference_temperature_degC=t_ref,
               temperature_at_epochs=tw.at_epochs, corrected_mm=d - b * dT,
               corrected_sigma_mm=np.sqrt((s * scale) ** 2 + (dT * sb) ** 2))
    if span >= 300 and temperature is not None:
        out["seasonal_amplitude_mm"] = float(abs(b) * _seasonal_temperature_amplitude(temperature))
    return out


def fit_target(t_days: npt.ArrayLike, d_mm: npt.ArrayLike, sigma_mm: npt.ArrayLike, *,
               temperature: tuple[np.ndarray, np.ndarray] | None = None, events: Sequence[Event] = (),
               reference_temperature: float | None = None) -> TargetFit:
    """Fit one target's history (see the module notes).

    Parameters
    ----------
    t_days, d_mm, sigma_mm : (n,) array-likes
        Epoch times (days from any origin), displacements and their sigmas (NaN displacements are left out).
    temperature : (times in days, degC), optional, keyword-only
        The temperature series on the same time axis.
    events : sequence of Event, keyword-only
    reference_temperature : float, optional, keyword-only
        Temperature the corrected series refers to (default: the median at the epochs).
    """
    t = np.asarray(t_days, dtype=np.float64)
    d = np.asarray(d_mm, dtype=np.float64)
    s = np.asarray(sigma_mm, dtype=np.float64)
    if not (t.shape == d.shape == s.shape) or t.ndim != 1:
        raise InputError("times, displacements and sigmas must be 1-D arrays of one length")
    ok = np.isfinite(t) & np.isfinite(d) & np.isfinite(s) & (s > 0)
    t, d, s = t[ok], d[ok], s[ok]
    n = len(t)
    data: dict[str, Any] = dict(n_epochs=n, epoch_days=t, corrected_mm=d, corrected_sigma_mm=s, measured_mm=d, measured_sigma_mm=s)
    if n < 4:
        return TargetFit(**data, notes=(f"only {n} epochs with a displacement: too few to fit (4 needed)",))
    notes: list[str] = []
    w = 1.0 / s ** 2
    to_fit, left_out = _events_to_fit(t, events)
    windows = temperature_windows(t, temperature, notes)
    best, per_law = search_models(t, d, w, model_specs(t, windows, to_fit, reference_temperature=reference_temperature))
    if best is None:
        return TargetFit(**data, notes=tuple(notes + ["the model cannot be fitted to these epochs"]))
    red = best.reduced_chi2
    scale = math.sqrt(red) if red > 1 else 1.0
    cov = best.cov * scale ** 2
    law = best.spec.creep_law
    # Akaike weights over the creep laws: their choice is uncertain too, and the thermal and event figures
    # carry that (model averaging, between-model spread added to the variances)
    models = per_law if len(per_law) > 1 else (best,)
    weights = akaike_weights(models)
    fields: dict[str, Any] = dict(data, scale=scale, rms_residual_mm=float(np.sqrt(np.mean(best.resid ** 2))),
                        creep_d_days=None if law is None else law[1],
                        creep_law=None if law is None else f"{law[0]}:{law[1]:g}")
    fields.update(_thermal_fit(best, models, weights, d, s, scale, temperature, float(t.max() - t.min())))
    i_r, i_as = best.index(Term("trend")), best.index(Term("annual_sin"))
    if i_r is not None:
        fields.update(trend_mm_per_year=float(best.coef[i_r]), trend_sigma=float(np.sqrt(max(cov[i_r, i_r], 0.0))))
    if i_as is not None:
        fields["seasonal_amplitude_mm"] = float(math.hypot(best.coef[i_as], best.coef[i_as + 1]))
    fitted = [_event_fit(e, models, weights, best, float(t.max())) for e, _ in to_fit]
    fields["events"] = tuple(sorted(left_out + fitted, key=lambda f: f.date))
    return TargetFit(**fields, notes=tuple(notes), predictor=Predictor(best.terms, best.coef, cov, law))


def first_crossing(fit: TargetFit, t_from: float, t_to: float, level_mm: float, *, step_days: float = 1.0
                   ) -> tuple[float, float, float] | None:
    """(central, earliest, latest) day on which the projection reaches ``|level_mm|``.

    The central estimate and the 2-sigma band's crossings; or None when even the band does not reach it before ``t_to``.
    """
    tq = np.arange(t_from, t_to + step_days, step_days)
    v, sg = fit.predict(tq)
    lvl = abs(level_mm)
    sign = 1.0 if level_mm >= 0 else -1.0
    central = tq[np.nonzero(sign * v >= lvl)[0]]
    early = tq[np.nonzero(sign * v + 2 * sg >= lvl)[0]]
    late = tq[np.nonzero(sign * v - 2 * sg >= lvl)[0]]
    if early.size == 0:
        return None
    return (float(central[0]) if central.size else float("nan"), float(early[0]),
            float(late[0]) if late.size else float("nan"))

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
reported as not determinable, never as a number.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np

from common.errors import InputError

CREEP_PSI = 0.6
CREEP_D_DAYS = tuple(float(v) for v in np.round(np.geomspace(3.0, 200.0, 19), 1))
CREEP_EXP_DAYS = tuple(float(v) for v in np.round(np.geomspace(5.0, 300.0, 19), 1))
#: Creep-time laws the fit chooses among (AICc) and averages over: the ACI 209 shape for several time
#: parameters, and an exponential approach 1 - exp(-t / tc) (a hyperbolic-like law with a different start).
CREEP_LAWS = tuple(("aci", d) for d in CREEP_D_DAYS) + tuple(("exp", tc) for tc in CREEP_EXP_DAYS)
WINDOWS_H = (1.0, 3.0, 6.0, 12.0, 24.0, 48.0, 168.0)
LAGS_H = (0.0, 3.0, 6.0)
YEAR_D = 365.25


def creep_shape(tau_days, law) -> np.ndarray:
    """The creep developed ``tau_days`` after loading as a share of the final creep (0 to 1).

    ``law`` is ``("aci", d)``: ``tau^0.6 / (d + tau^0.6)`` (ACI 209), ``("exp", tc)``: ``1 - exp(-tau / tc)``,
    or a bare number ``d`` for the ACI shape.
    """
    kind, p = ("aci", law) if not isinstance(law, tuple) else law
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


@dataclass(frozen=True)
class TargetFit:
    """Everything the model says about one target (mm, days, degrees Celsius)."""

    n_epochs: int
    thermal_mm_per_degC: float = float("nan")
    thermal_sigma: float = float("nan")
    thermal_p_value: float = float("nan")
    temperature_window_h: Optional[float] = None
    temperature_lag_h: Optional[float] = None
    reference_temperature_degC: Optional[float] = None
    events: tuple[EventFit, ...] = ()
    trend_mm_per_year: float = float("nan")
    trend_sigma: float = float("nan")
    seasonal_amplitude_mm: float = float("nan")
    creep_d_days: Optional[float] = None
    creep_law: Optional[str] = None
    scale: float = 1.0  # sqrt of the reduced chi-square applied to the sigmas
    rms_residual_mm: float = float("nan")
    corrected_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    corrected_sigma_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))
    temperature_at_epochs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    epoch_days: np.ndarray = field(default_factory=lambda: np.zeros(0))
    notes: tuple[str, ...] = ()
    _predict: object = None  # callable(t_days array) -> (value, sigma), for projections

    def predict(self, t_days) -> tuple[np.ndarray, np.ndarray]:
        if self._predict is None:
            raise InputError("this target's model could not be fitted")
        return self._predict(np.atleast_1d(np.asarray(t_days, dtype=np.float64)))


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


def _wls(X: np.ndarray, y: np.ndarray, w: np.ndarray):
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


def fit_target(t_days: Sequence[float], d_mm: Sequence[float], sigma_mm: Sequence[float], *,
               temperature: Optional[tuple[np.ndarray, np.ndarray]] = None, events: Sequence[Event] = (),
               reference_temperature: Optional[float] = None) -> TargetFit:
    """Fit one target's history (see the module notes).

    Parameters
    ----------
    t_days, d_mm, sigma_mm : (n,) sequences
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
    if n < 4:
        return TargetFit(n, epoch_days=t, corrected_mm=d, corrected_sigma_mm=s,
                         notes=(f"only {n} epochs with a displacement: too few to fit (4 needed)",))
    notes: list[str] = []
    w = 1.0 / s ** 2

    # events: which are determinable
    ev_cols, ev_fits = [], []
    for e in sorted(events, key=lambda e: e.t_days):
        before, after = int(np.sum(t < e.t_days)), int(np.sum(t >= e.t_days))
        if before < 2 or after < 2:
            ev_fits.append(EventFit(e.label, e.date, e.kind, note=f"not determinable: {before} epoch(s) before and "
                                                                    f"{after} after (2 each needed)"))
            continue
        ev_cols.append((e, after >= 3))

    temp_candidates = [(None, None, None)]
    if temperature is not None:
        tt, tv = (np.asarray(a, dtype=np.float64) for a in temperature)
        order = np.argsort(tt)
        tt, tv = tt[order], tv[order]
        cands = []
        for wh in WINDOWS_H:
            for lh in LAGS_H:
                te = effective_temperature(t, tt, tv, wh, lh)
                cands.append((wh, lh, te))
        best_cover = max(int(np.sum(np.isfinite(c[2]))) for c in cands)
        if best_cover < n:
            notes.append(f"the temperature series covers {best_cover} of {n} epochs; the thermal fit uses those")
        if best_cover >= 4:
            temp_candidates = [c for c in cands if int(np.sum(np.isfinite(c[2]))) == best_cover]
        else:
            notes.append("the temperature series does not overlap the epochs: no thermal fit")
    span = float(t.max() - t.min())
    best = None
    per_d: dict = {}  # the best model for each creep-time parameter, for model averaging
    for wh, lh, te in temp_candidates:
        use = np.ones(n, bool) if te is None else np.isfinite(te)
        t_ref = None
        if te is not None:
            t_ref = float(np.median(te[use])) if reference_temperature is None else float(reference_temperature)
        for dd in CREEP_LAWS if any(c for _, c in ev_cols) else (None,):
            for trend in (False, True):
                for annual in ((False, True) if te is None and span >= 300 else (False,)):
                    cols, names = [np.ones(n)], ["c"]
                    if te is not None:
                        cols.append(np.nan_to_num(te - t_ref))
                        names.append("b")
                    for e, creep in ev_cols:
                        h = (t >= e.t_days).astype(float)
                        cols.append(h)
                        names.append(("s", e))
                        if creep and dd is not None:
                            cols.append(h * creep_shape(t - e.t_days, dd))
                            names.append(("k", e))
                    if trend:
                        cols.append(t / YEAR_D)
                        names.append("r")
                    if annual:
                        cols += [np.sin(2 * np.pi * t / YEAR_D), np.cos(2 * np.pi * t / YEAR_D)]
                        names += ["as", "ac"]
                    X = np.column_stack(cols)[use]
                    if X.shape[0] <= X.shape[1] + 1 or np.linalg.matrix_rank(X) < X.shape[1]:
                        continue
                    coef, cov, chi2, aicc, resid = _wls(X, d[use], w[use])
                    cand = dict(aicc=aicc, coef=coef, cov=cov, chi2=chi2, names=names, use=use, te=te, t_ref=t_ref,
                                wh=wh, lh=lh, dd=dd, trend=trend, annual=annual, resid=resid)
                    if best is None or aicc < best["aicc"] - 1e-9:
                        best = cand
                    if dd not in per_d or aicc < per_d[dd]["aicc"] - 1e-9:
                        per_d[dd] = cand
    if best is None:
        return TargetFit(n, epoch_days=t, corrected_mm=d, corrected_sigma_mm=s,
                         notes=tuple(notes + ["the model cannot be fitted to these epochs"]))
    coef, cov, names, use = best["coef"], best["cov"], best["names"], best["use"]
    dof = int(use.sum()) - len(coef)
    red = best["chi2"] / max(dof, 1)
    scale = math.sqrt(red) if red > 1 else 1.0
    cov = cov * scale ** 2
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    idx = {k: i for i, k in enumerate(names) if isinstance(k, str)}

    out = dict(n_epochs=n, scale=scale, epoch_days=t, rms_residual_mm=float(np.sqrt(np.mean(best["resid"] ** 2))),
               creep_d_days=None if best["dd"] is None else best["dd"][1],
               creep_law=None if best["dd"] is None else f"{best['dd'][0]}:{best['dd'][1]:g}")
    # Akaike weights over the creep laws: their choice is uncertain too, and the thermal and event figures
    # carry that (model averaging, between-model spread added to the variances)
    models = list(per_d.values()) if len(per_d) > 1 else [best]
    a_min = min(m["aicc"] for m in models)
    wts = np.array([math.exp(-0.5 * (m["aicc"] - a_min)) for m in models])
    wts /= wts.sum()
    for m in models:  # each model's covariance scaled by its own reduced chi-square, and its column index
        red_m = m["chi2"] / max(int(m["use"].sum()) - len(m["coef"]), 1)
        m["scaled_cov"] = m["cov"] * (red_m if red_m > 1 else 1.0)
        m["pos"] = {n_: i for i, n_ in enumerate(m["names"])}

    def averaged(vals) -> tuple[float, float]:
        """Akaike-weighted mean and sigma of per-model (value, variance) pairs (NaN when a model lacks it)."""
        if any(v is None for v in vals):
            return float("nan"), float("nan")
        mean = float(sum(w_ * v[0] for w_, v in zip(wts, vals)))
        var = float(sum(w_ * (v[1] + (v[0] - mean) ** 2) for w_, v in zip(wts, vals)))
        return mean, math.sqrt(var)

    if "b" in idx:
        from scipy import stats

        b, sb = averaged([(float(m["coef"][m["pos"]["b"]]), float(m["scaled_cov"][m["pos"]["b"], m["pos"]["b"]]))
                          for m in models])
        out.update(thermal_mm_per_degC=b, thermal_sigma=sb,
                   thermal_p_value=float(2 * stats.t.sf(abs(b) / sb, max(dof, 1))) if sb > 0 else float("nan"),
                   temperature_window_h=best["wh"], temperature_lag_h=best["lh"],
                   reference_temperature_degC=best["t_ref"], temperature_at_epochs=best["te"])
        dT = np.nan_to_num(best["te"] - best["t_ref"])
        out["corrected_mm"] = d - b * dT
        out["corrected_sigma_mm"] = np.sqrt((s * scale) ** 2 + (dT * sb) ** 2)
        if span >= 300 and temperature is not None:
            tt, tv = (np.asarray(a, dtype=np.float64) for a in temperature)
            okk = np.isfinite(tv)
            A = np.column_stack([np.ones(okk.sum()), np.sin(2 * np.pi * tt[okk] / YEAR_D),
                                 np.cos(2 * np.pi * tt[okk] / YEAR_D)])
            ca, *_ = np.linalg.lstsq(A, tv[okk], rcond=None)
            out["seasonal_amplitude_mm"] = float(abs(b) * math.hypot(ca[1], ca[2]))
    else:
        out["corrected_mm"] = d
        out["corrected_sigma_mm"] = s * scale
    if "r" in idx:
        out.update(trend_mm_per_year=float(coef[idx["r"]]), trend_sigma=float(sig[idx["r"]]))
    if "as" in idx:
        out["seasonal_amplitude_mm"] = float(math.hypot(coef[idx["as"]], coef[idx["ac"]]))
    pos = {n_: i for i, n_ in enumerate(names)}

    def event_params(m, e) -> dict:
        """One model's (value, variance) of the event's step, creep and creep coefficients."""
        pm, cv = m["pos"], m["scaled_cov"]
        i_s = pm[("s", e)]
        step = float(m["coef"][i_s])
        out_m = {"s": (step, float(cv[i_s, i_s]))}
        if ("k", e) in pm:
            i_k = pm[("k", e)]
            k = float(m["coef"][i_k])
            f_last = float(creep_shape(t.max() - e.t_days, m["dd"]))
            c2 = cv[np.ix_([i_s, i_k], [i_s, i_k])]
            out_m["k"] = (k, float(cv[i_k, i_k]))
            # developed by the last epoch (what the dissertation reports) and the law's final value
            for key, kk in (("phi", k * f_last), ("phi_final", k)):
                scale_k = f_last if key == "phi" else 1.0
                g = np.array([-kk / step ** 2, scale_k / step]) if step != 0 else np.array([np.nan, np.nan])
                out_m[key] = (kk / step if step != 0 else float("nan"), float(max(g @ c2 @ g, 0.0)))
            out_m["creep_now"] = (k * f_last, float(f_last ** 2 * cv[i_k, i_k]))
        return out_m

    for e, creep in ev_cols:
        per_model = [event_params(m, e) for m in models]
        step, s_step = averaged([p.get("s") for p in per_model])
        fit = dict(step_mm=step, step_sigma_mm=s_step)
        if ("k", e) in pos:
            k, s_k = averaged([p.get("k") for p in per_model])
            phi, s_phi = averaged([p.get("phi") for p in per_model])
            phi_f, s_phi_f = averaged([p.get("phi_final") for p in per_model])
            now, s_now = averaged([p.get("creep_now") for p in per_model])
            fit.update(creep_mm=now, creep_sigma_mm=s_now, creep_final_mm=k, creep_final_sigma_mm=s_k,
                       creep_coefficient=phi, creep_coefficient_sigma=s_phi, creep_coefficient_final=phi_f,
                       creep_coefficient_final_sigma=s_phi_f)
            note = "" if abs(step) > 2 * s_step else "the step is within 2 sigma of zero: its creep coefficient is not determinable"
            if note:
                fit.update(creep_coefficient=float("nan"), creep_coefficient_sigma=float("nan"),
                           creep_coefficient_final=float("nan"), creep_coefficient_final_sigma=float("nan"))
        else:
            note = "creep not determinable: fewer than 3 epochs after the event"
        ev_fits.append(EventFit(e.label, e.date, e.kind, note=note, **fit))
    out["events"] = tuple(sorted(ev_fits, key=lambda f: f.date))

    def predict(tq, coef=coef, cov=cov, names=names, dd=best["dd"]):
        rows = []
        for name in names:
            if name == "c":
                rows.append(np.ones_like(tq))
            elif name == "b":
                rows.append(np.zeros_like(tq))  # at the reference temperature
            elif name == "r":
                rows.append(tq / YEAR_D)
            elif name == "as":
                rows.append(np.sin(2 * np.pi * tq / YEAR_D))
            elif name == "ac":
                rows.append(np.cos(2 * np.pi * tq / YEAR_D))
            elif name[0] == "s":
                rows.append((tq >= name[1].t_days).astype(float))
            else:
                rows.append((tq >= name[1].t_days) * creep_shape(tq - name[1].t_days, dd))
        J = np.column_stack(rows)
        return J @ coef, np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", J, cov, J), 0.0))
    out["_predict"] = predict
    out["notes"] = tuple(notes)
    return TargetFit(**out)


def first_crossing(fit: TargetFit, t_from: float, t_to: float, level_mm: float, *, step_days: float = 1.0
                   ) -> Optional[tuple[float, float, float]]:
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

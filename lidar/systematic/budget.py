"""Displacements from corrected centroids, with the error budget of every target.

:func:`corrected_displacements` corrects both visits' centroids with the campaign's
:class:`~lidar.systematic.adjustment.FieldModel` (:mod:`lidar.systematic.corrections`), runs the
displacement computation on them, and splits each displacement's variance into its terms (see
:data:`lidar.displacement_result.BUDGET_TERMS`): the target's own centroids (``noise``), the reference
motion and the deck normal (``frame``), the visit's atmospheric scale (``scale``), the instrument's biases
(``bias``: the range walk with the largest departure among the families the data cannot tell from it, see
:func:`~lidar.systematic.range_walk.family_spread2`, and the axis errors, :mod:`lidar.systematic.axes`) and
both visits' drift (``drift``). The reported sigma
is their sum in quadrature. The along-span movements carry the same terms.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from lidar.displacement import compute_displacements
from lidar.displacement_result import Displacement, EpochDisplacements, Observation, Sighted
from lidar.systematic.adjustment import FieldModel
from lidar.systematic.corrections import CorrectionJacobian, correct_visit, cos_incidence_of
from lidar.systematic.range_walk import design, family_spread2


def corrected_observations(centroids: Mapping[str, Sighted], model: FieldModel, label: str
                           ) -> tuple[dict[str, Observation], dict[str, CorrectionJacobian]]:
    """Corrected observations (covariance widened by the visit's misfit) and their Jacobians.

    A visit whose centroids the field model fits worse than their covariances say (``misfit`` > 1: something
    the model does not hold) has every centroid covariance scaled by the misfit squared. The spread of the
    range walk's families is left out of the observations' covariances: it is one error common to every
    target (a family moves all of them at once), which an observation's own covariance cannot hold without
    re-weighting the reference fit against it; it enters the budget through each family's deviations
    (:func:`family_deviations`) instead. The walk a strength step leaves uncertain at a disc whose rim returns
    straddle its threshold is the sighting's own (:meth:`~lidar.systematic.range_walk.RangeWalkModel.smear_m`):
    it widens that centroid's covariance along its line of sight.
    """
    vis = model.visit(label)
    inflate = max(1.0, vis.misfit) ** 2
    pos, jac = correct_visit(centroids, range_walk=model.range_walk, visit=vis, axes=model.axes)
    obs = {}
    for k, c in centroids.items():
        y = np.asarray(c.xyz_socs, dtype=np.float64)
        r = float(np.linalg.norm(y))
        u = y / r
        smear = float(model.range_walk.smear_m(r, cos_incidence_of(c))[0])
        obs[k] = Observation(pos[k], inflate * np.asarray(c.cov, dtype=np.float64) + smear ** 2 * np.outer(u, u))
    for k in vis.shifted:  # a moved pier's targets moved back: their position carries that shift's sigma
        if k in obs:
            u = np.asarray(vis.shift_socs, dtype=np.float64)
            obs[k] = Observation(obs[k].xyz, obs[k].cov + vis.shift_sigma_m ** 2 * np.outer(u, u))
    return obs, jac


def corrected_displacements(baseline: Mapping[str, Sighted], epoch: Mapping[str, Sighted], groups: Mapping[str, str],
                            *, model: FieldModel, baseline_label: str, epoch_label: str,
                            **options: object) -> EpochDisplacements:
    """Displacements of ``epoch`` against ``baseline`` after the field model's corrections, with their budget.

    Parameters
    ----------
    baseline, epoch : mapping reflector id -> centroid
        Found centroids with ``xyz_socs`` (3,) m, ``cov`` (3, 3) m^2, ``cos_incidence`` and ``time_s``
        (e.g. :class:`lidar.centroid.TargetCentroid`), each in its own visit's scanner frame.
    groups : mapping reflector id -> "reference" | "measurement"
    model : FieldModel, keyword-only
    baseline_label, epoch_label : str, keyword-only
        The two visits' labels in the model.
    **options
        Passed to :func:`lidar.displacement.compute_displacements`.

    Returns
    -------
    EpochDisplacements
        Each displacement's ``budget`` holds every term; ``sigma_m`` is their sum in quadrature.
    """
    b_obs, b_jac = corrected_observations(baseline, model, baseline_label)
    e_obs, e_jac = corrected_observations(epoch, model, epoch_label)
    res = compute_displacements(b_obs, e_obs, groups, **options)  # type: ignore[arg-type]
    sens = res.sensitivity
    if sens is None:
        return res
    jacs = {"baseline": b_jac, "epoch": e_jac}
    devs = {"baseline": family_deviations(baseline, model, baseline_label, {k: o.xyz for k, o in b_obs.items()}),
            "epoch": family_deviations(epoch, model, epoch_label, {k: o.xyz for k, o in e_obs.items()})}
    weights = np.array([a[2] for a in model.range_walk.alternatives])
    cov_theta = model.range_walk.covariance_m2
    cov_axes = model.axes.covariance_arcsec2
    v_base, v_ep = model.visit(baseline_label), model.visit(epoch_label)
    out = []
    for d in res.displacements:
        if d.reflector not in sens.targets:
            out.append(d)
            continue
        i = sens.targets.index(d.reflector)
        terms = _terms(sens.vertical[i], sens.inputs, jacs, cov_theta, v_base, v_ep, devs, weights, cov_axes)
        bias2 = terms["theta"] + terms["alternatives"] + terms["axes"]
        budget = {"noise": d.budget.get("noise", 0.0), "frame": d.budget.get("frame", 0.0),
                  "scale": np.sqrt(terms["scale"]),
                  "bias": np.sqrt(bias2), "drift": np.sqrt(terms["drift"])}
        sigma = float(np.sqrt(sum(v ** 2 for v in budget.values())))
        along_sigma = d.along_sigma_m
        if np.isfinite(d.along_m):
            ta = _terms(sens.along[i], sens.inputs, jacs, cov_theta, v_base, v_ep, devs, weights, cov_axes)
            along_sigma = float(np.sqrt(d.along_sigma_m ** 2 + ta["theta"] + ta["alternatives"] + ta["axes"]
                                        + ta["scale"] + ta["drift"]))
        out.append(replace(d, sigma_m=sigma, along_sigma_m=along_sigma,
                           budget={k: float(v) for k, v in budget.items()}))
    return replace(res, displacements=tuple(out))


def _terms(row: np.ndarray, inputs, jacs: Mapping[str, Mapping[str, CorrectionJacobian]], cov_theta: np.ndarray,
           v_base, v_ep, devs: Mapping[str, Mapping[str, np.ndarray]], weights: np.ndarray,
           cov_axes: np.ndarray) -> dict:
    """Variance terms (m^2) of one output (a row of the sensitivity) from the corrections' uncertainties.

    ``devs[side][id]`` is (n_alternatives, 3): how each supported range-walk family would move that
    corrected centroid against the chosen one; ``weights`` their BIC weights. ``cov_axes`` is the instrument's
    axis errors' covariance (arcsec^2; they are the same in both visits).
    """
    p = cov_theta.shape[0]
    j_theta = np.zeros(p)
    j_axes = np.zeros(cov_axes.shape[0])
    j_scale = 0.0
    j_drift = {"baseline": np.zeros(3), "epoch": np.zeros(3)}
    alt = np.zeros(weights.size)
    for n, (side, k) in enumerate(inputs):
        jb = row[3 * n:3 * n + 3]
        cj = jacs[side].get(k)
        if cj is None:
            continue
        j_theta += jb @ cj.d_theta
        j_axes += jb @ cj.d_axes
        if side == "epoch":
            j_scale += float(jb @ cj.d_scale)
        j_drift[side] += jb @ cj.d_drift
        if weights.size:
            alt += devs[side][k] @ jb
    return {"theta": float(j_theta @ cov_theta @ j_theta) if p else 0.0,
            "axes": float(j_axes @ cov_axes @ j_axes),
            "scale": j_scale ** 2 * (v_ep.scale_sigma_ppm ** 2),
            "drift": float(j_drift["baseline"] @ v_base.drift_cov @ j_drift["baseline"]
                           + j_drift["epoch"] @ v_ep.drift_cov @ j_drift["epoch"]),
            "alternatives": float(family_spread2(alt, weights))}


def family_deviations(centroids: Mapping[str, Sighted], model: FieldModel, label: str, corrected: Mapping[str, np.ndarray]
                ) -> dict[str, np.ndarray]:
    """(n_alternatives, 3) per centroid: the corrected position under each supported family minus the chosen one."""
    rw = model.range_walk
    vis = model.visit(label)
    n = len(rw.alternatives)
    out = {}
    for k, c in centroids.items():
        y = np.asarray(c.xyz_socs, dtype=np.float64)
        r = float(np.linalg.norm(y))
        u = y / r
        ci = cos_incidence_of(c)
        best = float(rw.bias_m(r, ci)[0])
        dev = np.zeros((n, 3))
        for a, (basis, coef, _) in enumerate(rw.alternatives):
            dev[a] = (float((design(basis, r, ci) @ coef)[0]) - best) * u
            if len(vis.alternative_scale_ppm) == n and label != model.baseline:
                dev[a] -= corrected[k] * 1e-6 * (vis.alternative_scale_ppm[a] - vis.scale_ppm)
        out[k] = dev
    return out


def displacement_terms_mm(d: Displacement) -> dict[str, float]:
    """A displacement's budget in millimetres (``sigma_noise_mm`` ...), NaN for terms it does not have."""
    return {f"sigma_{k}_mm": float(d.budget.get(k, np.nan)) * 1e3 for k in ("noise", "frame", "scale", "bias",
                                                                              "drift")}


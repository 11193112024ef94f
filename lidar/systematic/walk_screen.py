"""Every range-walk law screened at once: the campaign adjustment linearised in the targets' range biases.

:func:`lidar.systematic.adjustment.fit_field_model` chooses the range walk's family by BIC, and a step of the
walk at a threshold of the return strength, the incidence's cosine or the range's ``(r0/r)^2`` is a family for
every threshold between two of the campaign's values. Fitting the adjustment for each of them costs three
Gauss-Newton iterations; a sparse search among them missed the threshold that fitted best, by a wide margin
(a step at strength 0.49, 25 BIC units better than the law chosen, left 5-7 sigma errors).

The adjustment is linear in the walk: at a solution of a general family the poses, scales, drifts and target
positions move little, and once they are eliminated every sighting's own range bias ``b`` (mm) enters through
one matrix of the campaign, ``M = J_b^T (I - P) J_b`` (``P`` the projection on the other unknowns' columns,
every row whitened), and one vector, ``g = J_b^T (I - P) e_0`` (``e_0`` the residuals without a walk). A law of
design ``D`` (sightings x P) then fits with::

    chi2(D) = chi2_0 - g^T D (D^T M D + I / prior^2)^-1 D^T g

so every threshold of every proxy is screened for the cost of a few small solves, and only the best are
fitted in full.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from common.rigid import rotations_from_rotvecs
from lidar.systematic.axes import ARCSEC
from lidar.systematic.range_walk import PRIOR_BIAS_MM, STEP_PROXIES, candidate_bases, design, step_name

if TYPE_CHECKING:  # the adjustment builds on this module; its problem is only named here
    from lidar.systematic.adjustment import AdjustmentProblem


@dataclass(frozen=True, eq=False)
class BiasInformation:
    """What a campaign's adjustment knows about its sightings' range biases (see the module's notes).

    Attributes
    ----------
    information : (S, S) float64 array
        ``M``, per mm^2 of bias, the other unknowns eliminated.
    gradient : (S,) float64 array
        ``g``, per mm of bias, at no walk.
    chi2_without : float
        The adjustment's chi-square with no walk, the other unknowns re-fitted (linearised).
    range_m, cos_incidence : (S,) float64 arrays
        Every sighting's, in the order of the rows of ``information``.
    scale_at_zero : (V,) float64 array
        Every visit's scale (ppm) with no walk, the other unknowns re-fitted (linearised); 0 for the baseline.
    scale_rows : (V, X + S) float64 array
        How each visit's scale moves with a step of the shared unknowns (X target unknowns, then the S biases).
    shared : tuple of (X, X), (X, S), (X,) arrays
        The target unknowns' normal matrix inverse, their coupling to the biases and right-hand side.
    """

    information: np.ndarray
    gradient: np.ndarray
    chi2_without: float
    range_m: np.ndarray
    cos_incidence: np.ndarray
    scale_at_zero: np.ndarray
    scale_rows: np.ndarray
    shared: tuple[np.ndarray, np.ndarray, np.ndarray]

    def scales_ppm(self, design_matrix: np.ndarray, theta_mm: np.ndarray) -> np.ndarray:
        """(V,) every visit's scale (ppm) under a walk law of the given design and coefficients (linearised)."""
        bias = np.asarray(design_matrix, dtype=np.float64) @ np.asarray(theta_mm, dtype=np.float64)
        inv_xx, n_xw, rhs_x = self.shared
        step = np.concatenate([inv_xx @ (rhs_x - n_xw @ bias), bias])
        return self.scale_at_zero - self.scale_rows @ step

    def chi2(self, design_matrix: np.ndarray) -> tuple[float, np.ndarray]:
        """The linearised chi-square of a walk law and its coefficients (mm).

        Parameters
        ----------
        design_matrix : (S, P) array
            The law's basis functions at every sighting (:func:`lidar.systematic.range_walk.design`).

        Returns
        -------
        chi2 : float
        theta_mm : (P,) array
        """
        d = np.asarray(design_matrix, dtype=np.float64)
        if d.shape[1] == 0:
            return self.chi2_without, np.zeros(0)
        dg = d.T @ self.gradient
        n = d.T @ self.information @ d + np.eye(d.shape[1]) / PRIOR_BIAS_MM ** 2
        theta = np.linalg.lstsq(n, dg, rcond=None)[0]
        return self.chi2_without - float(dg @ theta), theta


def bias_information(problem: AdjustmentProblem) -> BiasInformation:
    """The :class:`BiasInformation` of an adjustment with no walk (``basis ()``) at its current unknowns."""
    if problem.basis:
        raise ValueError("bias_information needs the adjustment without a walk (basis ())")
    sizes = [len(v.refs) + len(v.decks) for v in problem.visits]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    n_walk, n_x = int(offsets[-1]), problem.n_shared
    normal = np.zeros((n_x + n_walk, n_x + n_walk))
    rhs = np.zeros(n_x + n_walk)
    chi2 = 0.0
    r_all, c_all = [], []
    scale0 = np.zeros(len(problem.visits))
    scale_rows = np.zeros((len(problem.visits), n_x + n_walk))
    for i, (v, start) in enumerate(zip(problem.visits, offsets[:-1], strict=False)):
        jl, js, res, _ = problem.visit_rows(v)
        jb = _bias_columns(problem, v)
        shared = np.zeros((js.shape[0], n_x + n_walk))
        shared[:, :n_x] = js
        shared[:jb.shape[0], n_x + start:n_x + start + jb.shape[1]] = jb
        inv_ll = np.linalg.pinv(jl.T @ jl + 1e-12 * np.eye(v.n_local)) if v.n_local else np.zeros((0, 0))
        b_l = -jl.T @ res
        n_ls = jl.T @ shared
        normal += shared.T @ shared - n_ls.T @ inv_ll @ n_ls
        rhs += -shared.T @ res - n_ls.T @ inv_ll @ b_l
        chi2 += float(res @ res) - float(b_l @ inv_ll @ b_l)
        if not v.is_base:  # the scale is the visit's 7th local unknown (after rotation and translation)
            scale0[i] = v.kappa_ppm + float((inv_ll @ b_l)[6])
            scale_rows[i] = (inv_ll @ n_ls)[6]
        sights = [s for s, _ in v.refs] + [s for s, _ in v.decks]
        r_all += [float(np.linalg.norm(s.xyz_socs)) for s in sights]
        c_all += [float(s.cos_incidence) for s in sights]
    prior_diag, prior_rhs, prior_chi2 = problem.priors()  # the axis errors' (no walk here)
    normal[:n_x, :n_x] += np.diag(prior_diag)
    rhs[:n_x] += prior_rhs
    chi2 += prior_chi2
    n_xx, n_xw = normal[:n_x, :n_x], normal[:n_x, n_x:]
    inv_xx = np.linalg.pinv(n_xx)
    info = normal[n_x:, n_x:] - n_xw.T @ inv_xx @ n_xw
    grad = rhs[n_x:] - n_xw.T @ inv_xx @ rhs[:n_x]
    chi2 -= float(rhs[:n_x] @ inv_xx @ rhs[:n_x])
    return BiasInformation(0.5 * (info + info.T), grad, chi2, np.asarray(r_all), np.asarray(c_all), scale0,
                           scale_rows, (inv_xx, n_xw, rhs[:n_x]))


def _bias_columns(problem: AdjustmentProblem, v) -> np.ndarray:
    """(data rows, sightings) whitened derivative of a visit's residuals by each sighting's range bias (mm).

    A bias ``b`` moves a centroid ``b u`` along its line of sight before the drift's rotation (as
    ``AdjustmentProblem._corrected`` corrects it); the rows are :meth:`AdjustmentProblem.visit_rows`' reference and deck rows.
    """
    a = v.arrays
    nr, nd = len(v.refs), len(v.decks)
    k = ARCSEC * a["dt"] / 3600.0
    dz = np.einsum("nij,nj->ni", rotations_from_rotvecs(v.omega[None, :] * k[:, None]), a["u"]) * 1e-3
    lw, qa, wt = problem.row_weights(v)
    out = np.zeros((3 * nr + nd, nr + nd))
    for j in range(nr):
        out[3 * j:3 * j + 3, j] = lw[j] @ dz[j]
    sc = 1.0 + 1e-6 * v.kappa_ppm
    for m in range(nd):
        out[3 * nr + m, nr + m] = wt[m] * float(qa @ dz[nr + m]) / sc
    return out


@dataclass(frozen=True, eq=False)
class LawFit:
    """A range-walk law as screened: its basis, BIC (up to a constant shared by all laws) and coefficients."""

    basis: tuple[str, ...]
    bic: float
    theta_mm: np.ndarray


def screen_laws(info: BiasInformation, n_data: int, *, min_side: int = 3) -> list[LawFit]:
    """Every smooth family and a constant plus a step at every threshold of every proxy, screened linearly.

    Parameters
    ----------
    info : BiasInformation
    n_data : int
        The adjustment's data rows (the BIC's log-n).
    min_side : int, keyword-only
        A step leaves at least this many sightings on each side (default 3): one that sets apart one or two
        sightings fits their noise, not a law.

    Returns
    -------
    list of LawFit, the smooth families of :func:`~lidar.systematic.range_walk.candidate_bases` first.

    Notes
    -----
    A step's BIC counts its threshold: the step of one proxy is one family whose threshold is chosen among its
    ``N`` candidates, each a priori ``1 / N`` of it, which adds ``2 ln N`` (:func:`threshold_penalty`). Without
    it the best of some 250 thresholds fitted the noise of campaigns with no walk at all: on the field-effects
    bench's campaigns without a walk a constant plus a step at strength 0.23 was chosen, 1-2 BIC units below no
    walk, and its -0.23 mm moved the displacements (0.079 mm RMS, 0.065 with the threshold counted; issue 39).
    """
    per_param = float(np.log(max(n_data, 2)))
    out = []
    for basis in candidate_bases():
        chi2, theta = info.chi2(design(basis, info.range_m, info.cos_incidence))
        out.append(LawFit(basis, chi2 + per_param * len(basis), theta))
    for proxy, g in STEP_PROXIES.items():
        out += _steps(info, proxy, np.asarray(g(info.range_m, info.cos_incidence), dtype=np.float64),
                      per_param, min_side)
    return out


def threshold_penalty(candidates: int) -> float:
    """What choosing a step's threshold among ``candidates`` adds to its BIC: ``2 ln N`` (a uniform prior over them)."""
    return 2.0 * float(np.log(max(int(candidates), 1)))


def _steps(info: BiasInformation, proxy: str, values: np.ndarray, per_param: float, min_side: int) -> list[LawFit]:
    """A constant plus a step at every midpoint between the sorted ``values`` (suffix sums: O(S^2) for all)."""
    order = np.argsort(values, kind="stable")
    v = values[order]
    m = info.information[np.ix_(order, order)]
    g = info.gradient[order]
    s = v.size
    ks = np.flatnonzero(v[1:] > v[:-1]) + 1  # the step sets apart sightings k.. (sorted), k = 1 .. S-1
    ks = ks[(ks >= min_side) & (ks <= s - min_side)]
    if ks.size == 0:
        return []
    col = m.sum(axis=0)
    col_suffix = np.concatenate([np.cumsum(col[::-1])[::-1], [0.0]])  # sum over rows and columns k..
    corner = np.cumsum(np.cumsum(m[::-1, ::-1], axis=0), axis=1)[::-1, ::-1]  # corner[k, k] = sum(m[k:, k:])
    g_suffix = np.concatenate([np.cumsum(g[::-1])[::-1], [0.0]])
    prior = 1.0 / PRIOR_BIAS_MM ** 2
    per_law = 2 * per_param + threshold_penalty(ks.size)
    a11 = float(m.sum()) + prior
    a12 = col_suffix[ks]
    a22 = corner[ks, ks] + prior
    b1, b2 = float(g.sum()), g_suffix[ks]
    det = a11 * a22 - a12 ** 2
    t1 = (a22 * b1 - a12 * b2) / det
    t2 = (a11 * b2 - a12 * b1) / det
    chi2 = info.chi2_without - (b1 * t1 + b2 * t2)
    thresholds = 0.5 * (v[ks - 1] + v[ks])
    return [LawFit(("1", step_name(proxy, float(t))), float(c) + per_law, np.array([a, b]))
            for t, c, a, b in zip(thresholds, chi2, t1, t2, strict=False)]

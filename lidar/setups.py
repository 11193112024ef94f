"""Visits with several set-ups: each set-up measured in its own frame, then joined through the targets they share.

A long bridge, or a pier hiding half the targets, needs two stations in one visit. Each set-up is measured in
its own scanner frame (stage 1) and corrected by the campaign's field model as a visit of its own (label
``L#2`` for set-up 2 of epoch ``L``: its own pose, scale and drift). Then the set-ups of the visit are joined
into set-up 1's frame by a multi-station adjustment, as RiSCAN's MSA does for scan positions:

* unknowns: every further set-up's rigid motion onto set-up 1 and every target's position in set-up 1's frame;
* observations: every corrected centroid, weighted by its covariance (``y_sj = R_s^T (X_j - t_s)``);
* Gauss-Newton; a target seen from two set-ups is measured once, its sightings combined by their inverse
  covariances, and the motions' uncertainty is carried into every position (the full covariance of the
  joined positions and their gain on every centroid are kept);
* when the shared sightings disagree more than their covariances say (the join's RMS normalised residual
  ``sigma0`` above 1), the budget of every displacement is summed from covariances scaled by ``sigma0**2`` (the a
  posteriori variance factor; the weights stay as measured); a weak sighting of a target another set-up sees better is left out (:func:`without_weak_duplicates`).

A set-up that shares fewer than three well-spread targets with the set-ups joined before it cannot be placed:
it is refused with the reason (:data:`common.flags.FLAG_SETUP_NOT_JOINED` on the epoch). A shared target
whose sightings disagree beyond :data:`OUTLIER_SIGMA` is left out of the motion and measured from its more
precise sighting (:data:`common.flags.FLAG_SETUP_JOIN_MISFIT`).

:func:`joined_displacements` then computes the displacements on the joined positions, and each one's error
budget keeps its terms (:mod:`lidar.systematic.budget`): ``noise`` from the target's own centroids, ``frame``
from every other centroid, the join's motions included, ``scale`` and ``drift`` from each set-up's own terms,
``bias`` from the range walk.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from common.errors import ProcessingError
from common.flags import FLAG_SETUP_JOIN_MISFIT, FLAG_SETUP_JOIN_WEAK, FLAG_SETUP_NOT_JOINED
from common.rigid import fit_rigid, rotation_from_rotvec, skew
from lidar.centroid import is_weak
from lidar.displacement import compute_displacements
from lidar.displacement_result import EpochDisplacements, Observation
from lidar.systematic.adjustment import ARCSEC, FieldModel
from lidar.systematic.budget import corrected_observations, family_deviations
from lidar.systematic.corrections import CorrectionJacobian
from lidar.systematic.range_walk import family_spread2

#: Shared targets must spread at least this far off their best-fitting line (metres, RMS) to fix a rotation.
MIN_SPREAD_M = 0.5
#: Fewest shared targets that place a set-up.
MIN_SHARED = 3
#: A shared target whose sightings disagree by more than this many sigmas is left out of the join's motion.
OUTLIER_SIGMA = 4.0
#: Gauss-Newton iterations of the join.
ITERATIONS = 6


def visit_label(label: str, setup: int) -> str:
    """The field model's visit label of an epoch's set-up: the epoch's own for set-up 1, ``L#k`` for the others.

    Examples
    --------
    >>> visit_label("2026-03-02", 1), visit_label("2026-03-02", 2)
    ('2026-03-02', '2026-03-02#2')
    """
    return label if setup == 1 else f"{label}#{setup}"


def spread_m(xyz: np.ndarray) -> float:
    """RMS distance of points from their best-fitting line, metres (0 for fewer than 3).

    Examples
    --------
    >>> round(spread_m(np.array([[0.0, 0, 0], [10, 0, 0], [20, 0, 0]])), 6)
    0.0
    >>> spread_m(np.array([[0.0, 0, 0], [10, 0, 0], [0, 4, 0], [10, 4, 0]]))
    2.0
    """
    p = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if len(p) < 3:
        return 0.0
    s = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    return float(np.sqrt(np.sum(s[1:] ** 2) / len(p)))


@dataclass(frozen=True, eq=False)
class SetupJoin:
    """The set-ups of one visit joined into set-up 1's frame.

    Attributes
    ----------
    label : str
        The epoch.
    joined : tuple of int
        The set-ups in the joint frame, set-up 1 first.
    refused : mapping set-up -> str
        Set-ups that could not be placed, with the reason.
    targets : tuple of str
        The joined targets, in the order of ``positions`` and ``covariance``.
    positions : (N, 3) float64
        Their positions in set-up 1's frame, metres.
    covariance : (3N, 3N) float64
        Their full covariance (the motions' uncertainty and the correlations it brings included), m^2.
    sightings : tuple of (int, str)
        Every centroid used, as (set-up, target), in the column order of ``gain``.
    gain : (3N, 3M) float64
        d positions / d centroids (each centroid in its own set-up's frame).
    sighting_cov : (M, 3, 3) float64
        The centroids' covariances as the join weighted them, m^2.
    motions : mapping set-up -> dict
        Each further set-up's motion onto set-up 1: ``rotation`` (3, 3), ``translation`` (3,), ``cov`` (6, 6)
        (rotation vector in rad, translation in m), the ``shared`` targets and their ``spread_m``.
    residuals : tuple of dict
        Per shared sighting: set-up, target, residual (mm, set-up 1's axes) and normalised residual.
    left_out : tuple of (int, str)
        Shared sightings left out of the motions (their sightings disagreed), with the target kept from the other.
    sigma0 : float
        RMS normalised residual of the join (1: the centroids agree as their covariances say).
    weak : mapping set-up -> tuple of str
        The further set-ups joined through fewer than :data:`MIN_SHARED` targets seen well from both sides, with the
        weak ones they were joined through (:func:`corrected_side` sets it from the centroids' flags).
    """

    label: str
    joined: tuple[int, ...]
    refused: Mapping[int, str]
    targets: tuple[str, ...]
    positions: np.ndarray
    covariance: np.ndarray
    sightings: tuple[tuple[int, str], ...]
    gain: np.ndarray
    sighting_cov: np.ndarray
    motions: Mapping[int, dict] = field(default_factory=dict)
    residuals: tuple[dict, ...] = ()
    left_out: tuple[tuple[int, str], ...] = ()
    sigma0: float = 1.0
    weak: Mapping[int, tuple[str, ...]] = field(default_factory=dict)

    def observations(self) -> dict[str, Observation]:
        """The joined targets as observations (position, its 3x3 block of the covariance)."""
        return {t: Observation(self.positions[i], self.covariance[3 * i:3 * i + 3, 3 * i:3 * i + 3])
                for i, t in enumerate(self.targets)}

    def flags(self) -> list[str]:
        """The epoch flags the join raises: set-ups refused (problem), sightings left out (warning)."""
        out = [f"{FLAG_SETUP_NOT_JOINED}: set-up {k} {why}" for k, why in sorted(self.refused.items())]
        if self.left_out:
            names = ", ".join(f"{t} from set-up {k}" for k, t in self.left_out)
            out.append(f"{FLAG_SETUP_JOIN_MISFIT}: {names} left out of the join (its sightings disagreed beyond "
                       f"{OUTLIER_SIGMA:g} sigma)")
        for k, ids in sorted(self.weak.items()):
            out.append(f"{FLAG_SETUP_JOIN_WEAK}: set-up {k} joined through {', '.join(ids)}, seen only weakly from "
                       f"both sides (rotation sigma {self._rotation_sigma_arcsec(k):.0f}\")")
        return out

    def _rotation_sigma_arcsec(self, k: int) -> float:
        m = self.motions.get(k)
        if m is None:
            return float("nan")
        return float(np.linalg.norm(np.sqrt(np.maximum(np.diag(m["cov"])[:3], 0.0)))) / ARCSEC

    def to_json(self) -> dict:
        """The joint frame's QA trail: what was joined or refused, each motion's sigma, the residuals."""
        motions = []
        for k, m in sorted(self.motions.items()):
            sd = np.sqrt(np.maximum(np.diag(m["cov"]), 0.0))
            res = [r for r in self.residuals if r["setup"] == k]
            rms = math.sqrt(float(np.mean([r["residual_mm"] ** 2 for r in res]))) if res else float("nan")
            motions.append({"setup": k, "shared": list(m["shared"]), "spread_m": round(float(m["spread_m"]), 3),
                            "rotation_sigma_arcsec": round(float(np.linalg.norm(sd[:3])) / ARCSEC, 3),
                            "translation_sigma_mm": round(float(np.linalg.norm(sd[3:])) * 1e3, 4),
                            "rms_mm": None if not math.isfinite(rms) else round(rms, 4)})
        return {"setups": sorted(set(self.joined) | set(self.refused)), "joined": list(self.joined),
                "refused": {str(k): v for k, v in sorted(self.refused.items())}, "sigma0": round(self.sigma0, 3),
                "motions": motions, "residuals": [dict(r) for r in self.residuals],
                "left_out": [{"setup": k, "reflector": t} for k, t in self.left_out],
                **({"weak": {str(k): list(v) for k, v in sorted(self.weak.items())}} if self.weak else {})}


def _place(sides: Mapping[int, Mapping[str, Observation]], order: Sequence[int]
           ) -> tuple[dict[int, tuple[np.ndarray, np.ndarray]], dict[int, str], dict[int, list[str]]]:
    """First motions of the further set-ups onto the first, each through the targets placed before it."""
    first = order[0]
    placed = {t: np.asarray(o.xyz, dtype=np.float64) for t, o in sides[first].items()}
    motions = {first: (np.eye(3), np.zeros(3))}
    shared_of: dict[int, list[str]] = {first: []}
    pending = list(order[1:])
    progress = True
    while pending and progress:
        progress = False
        for k in list(pending):
            shared = sorted(t for t in sides[k] if t in placed)
            if len(shared) < MIN_SHARED or spread_m(np.array([placed[t] for t in shared])) < MIN_SPREAD_M:
                continue
            fit = fit_rigid(np.array([sides[k][t].xyz for t in shared]), np.array([placed[t] for t in shared]))
            motions[k] = (fit.rotation, fit.translation)
            shared_of[k] = shared
            for t, o in sides[k].items():
                placed.setdefault(t, fit.apply(np.asarray(o.xyz)[None])[0])
            pending.remove(k)
            progress = True
    refused = {}
    for k in pending:
        shared = sorted(t for t in sides[k] if t in placed)
        if len(shared) < MIN_SHARED:
            refused[k] = (f"shares {len(shared)} target(s) with the set-ups before it ({', '.join(shared) or 'none'}); "
                          f"{MIN_SHARED} well-spread ones are needed to join it: re-scan from a station that sees "
                          "them, or add targets both stations see")
        else:
            refused[k] = (f"shares {len(shared)} targets ({', '.join(shared)}) but they lie on a line (spread "
                          f"{spread_m(np.array([placed[t] for t in shared])):.2f} m, {MIN_SPREAD_M:g} m needed): "
                          "the rotation about it is undetermined; re-scan from a station that sees targets off it")
    return motions, refused, shared_of


class _Join:
    """The linearised multi-station adjustment of one visit (see the module notes)."""

    def __init__(self, sides: Mapping[int, Mapping[str, Observation]], motions: Mapping[int, tuple],
                 skip: set[tuple[int, str]]):
        self.order = sorted(motions)
        self.sides = sides
        self.obs = [(k, t) for k in self.order for t in sorted(sides[k])]
        self.targets = sorted({t for _, t in self.obs})
        self.index = {t: i for i, t in enumerate(self.targets)}
        self.local = {k: n for n, k in enumerate(self.order[1:])}  # motion unknowns: 6 per further set-up
        self.skip = skip
        self.rot = {k: np.asarray(motions[k][0], dtype=np.float64) for k in self.order}
        self.tr = {k: np.asarray(motions[k][1], dtype=np.float64) for k in self.order}
        self.x = np.zeros((len(self.targets), 3))
        for k, t in reversed(self.obs):  # set-up 1's sighting wins the start
            self.x[self.index[t]] = self.rot[k] @ np.asarray(sides[k][t].xyz) + self.tr[k]
        self.cov = np.array([np.asarray(sides[k][t].cov, dtype=np.float64) for k, t in self.obs]).reshape(-1, 3, 3)

    @property
    def n_unknowns(self) -> int:
        return 6 * len(self.local) + 3 * len(self.targets)

    def rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(residuals (3M,), d model / d unknowns (3M, U), weights (3M, 3M)) at the current unknowns."""
        m = len(self.obs)
        r = np.zeros(3 * m)
        f = np.zeros((3 * m, self.n_unknowns))
        w = np.zeros((3 * m, 3 * m))
        nm = 6 * len(self.local)
        for n, (k, t) in enumerate(self.obs):
            rk, tk, xj = self.rot[k], self.tr[k], self.x[self.index[t]]
            rows = slice(3 * n, 3 * n + 3)
            r[rows] = np.asarray(self.sides[k][t].xyz) - rk.T @ (xj - tk)
            j = nm + 3 * self.index[t]
            f[rows, j:j + 3] = rk.T
            if k in self.local:
                c = 6 * self.local[k]
                f[rows, c:c + 3] = rk.T @ skew(xj - tk)
                f[rows, c + 3:c + 6] = -rk.T
            shared = sum(1 for kk, tt in self.obs if tt == t) > 1
            if not ((k, t) in self.skip and shared):
                w[rows, rows] = np.linalg.inv(self.cov[n])
        return r, f, w

    def step(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One Gauss-Newton step; returns (inverse normal matrix, d model, weights, residuals) before it."""
        r, f, w = self.rows()
        n_inv = np.linalg.pinv(f.T @ w @ f)
        dx = n_inv @ f.T @ w @ r
        nm = 6 * len(self.local)
        for k, c in self.local.items():
            self.rot[k] = rotation_from_rotvec(dx[6 * c:6 * c + 3]) @ self.rot[k]
            self.tr[k] = self.tr[k] + dx[6 * c + 3:6 * c + 6]
        self.x = self.x + dx[nm:].reshape(-1, 3)
        return n_inv, f, w, r


def _disagreements(j: _Join) -> list[tuple[float, int, str]]:
    """(normalised disagreement, set-up, target) of every further sighting of a shared target against the others."""
    out = []
    for t in j.targets:
        seen = [(n, k) for n, (k, tt) in enumerate(j.obs) if tt == t and (k, t) not in j.skip]
        if len(seen) < 2:
            continue
        pos = {k: j.rot[k] @ np.asarray(j.sides[k][t].xyz) + j.tr[k] for _, k in seen}
        cov = {k: j.rot[k] @ j.cov[n] @ j.rot[k].T for n, k in seen}
        for _, k in seen[1:]:
            ref = seen[0][1]
            d = pos[k] - pos[ref]
            out.append((math.sqrt(float(d @ np.linalg.solve(cov[k] + cov[ref], d)) / 3.0), k, t))
    return out


def _worse(j: _Join, k: int, t: str) -> tuple[int, str]:
    """Of a disagreeing target's sightings (set-up ``k`` against the first), the less precise one."""
    first = next(kk for kk, tt in j.obs if tt == t and (kk, t) not in j.skip)
    trace = {kk: float(np.trace(j.cov[n])) for n, (kk, tt) in enumerate(j.obs) if tt == t and kk in (k, first)}
    return (k, t) if trace[k] >= trace[first] else (first, t)


def join_setups(label: str, sides: Mapping[int, Mapping[str, Observation]]) -> SetupJoin:
    """Join the set-ups of one visit into set-up 1's frame (see the module notes).

    Parameters
    ----------
    label : str
        The epoch, for messages.
    sides : mapping set-up -> (mapping target -> Observation)
        Each set-up's corrected centroids in its own scanner frame (metres, m^2). The lowest set-up
        number with centroids is the joint frame.

    Returns
    -------
    SetupJoin
    """
    order = sorted(k for k, v in sides.items() if v)
    if not order:
        raise ProcessingError(f"epoch {label}: no set-up has a measured target to join")
    motions, refused, shared_of = _place(sides, order)
    skip: set[tuple[int, str]] = set()
    while True:
        j = _Join(sides, motions, skip)
        for _ in range(ITERATIONS):
            j.step()
        bad = [b for b in _disagreements(j) if b[0] > OUTLIER_SIGMA]
        motions = {k: (j.rot[k], j.tr[k]) for k in j.order}
        if not bad:
            break
        _, k, t = max(bad)
        usable = [tt for tt in shared_of.get(k, []) if (k, tt) not in skip and tt != t]
        if len(usable) < MIN_SHARED:
            break
        skip.add(_worse(j, k, t))
    return _finish(label, j, refused, shared_of, skip)


def _finish(label: str, j: _Join, refused: Mapping[int, str], shared_of: Mapping[int, list], skip: set
            ) -> SetupJoin:
    """The join's covariance, gain, residuals and motions at its solution."""
    n_inv, f, w, r = j.step()  # one more step from the solution: the linearisation the covariance needs
    used = [n for n in range(len(j.obs)) if np.any(w[3 * n:3 * n + 3, 3 * n:3 * n + 3])]
    dof = 3 * len(used) - np.linalg.matrix_rank(f.T @ w @ f)
    chi2 = float(r @ w @ r)
    s0 = math.sqrt(chi2 / dof) if dof > 0 else 1.0
    nm = 6 * len(j.local)
    gain_all = n_inv @ f.T @ w  # d unknowns / d centroids
    gain = gain_all[nm:]
    cov_all = gain_all @ _block_diag(j.cov) @ gain_all.T
    # the a posteriori variance factor: sightings that disagree more than their covariances say are less certain
    # than they say, every one of them (never made more certain when they agree better). It widens the budget
    # each displacement's sigma is summed from (through ``sighting_cov``), not the weights: the positions'
    # covariance the displacement computation weighs the targets and chooses the deck normal by stays as measured
    sighting_cov = j.cov * max(1.0, s0) ** 2
    motions = {}
    for k, c in j.local.items():
        motions[k] = {"rotation": j.rot[k], "translation": j.tr[k],
                      "cov": cov_all[6 * c:6 * c + 6, 6 * c:6 * c + 6], "shared": shared_of.get(k, []),
                      "spread_m": spread_m(np.array([j.x[j.index[t]] for t in shared_of.get(k, [])]))}
    residuals = []
    for n, (k, t) in enumerate(j.obs):
        if sum(1 for _, tt in j.obs if tt == t) < 2:
            continue
        e = j.rot[k] @ r[3 * n:3 * n + 3]  # in set-up 1's axes
        norm = math.sqrt(float(r[3 * n:3 * n + 3] @ np.linalg.solve(j.cov[n], r[3 * n:3 * n + 3])) / 3.0)
        residuals.append({"setup": k, "reflector": t, "residual_mm": round(float(np.linalg.norm(e)) * 1e3, 4),
                          "residual_xyz_mm": [round(float(v) * 1e3, 4) for v in e],
                          "normalised": round(norm, 3), "left_out": (k, t) in skip})
    return SetupJoin(label, tuple(j.order), dict(refused), tuple(j.targets), j.x.copy(), cov_all[nm:, nm:],
                     tuple(j.obs), gain, sighting_cov, motions, tuple(residuals), tuple(sorted(skip)), s0)


def _block_diag(blocks: np.ndarray) -> np.ndarray:
    m = len(blocks)
    out = np.zeros((3 * m, 3 * m))
    for n in range(m):
        out[3 * n:3 * n + 3, 3 * n:3 * n + 3] = blocks[n]
    return out


# ------------------------------------------------------------------------------------------ displacements
@dataclass(frozen=True, eq=False)
class CorrectedVisit:
    """One side (baseline or epoch) of the displacement computation: its set-ups corrected and joined."""

    join: SetupJoin
    jacobians: Mapping[tuple[int, str], CorrectionJacobian]  # (set-up, target) -> its Jacobian
    deviations: Mapping[tuple[int, str], np.ndarray]
    visits: Mapping[int, str]  # set-up -> field-model visit label


def without_weak_duplicates(setups: Mapping[int, Mapping[str, Any]]) -> dict[int, dict[str, Any]]:
    """Each set-up's centroids less the weak sightings of targets another set-up sees better.

    A weak sighting (a disc narrower than :data:`lidar.centroid.WEAK_RATIO` of the beam, :func:`lidar.centroid.is_weak`)
    is millimetres off along its line of sight, which its covariance covers on its own; joined with another
    set-up's sharp sighting of the same target it still pulls the set-ups' motion (on the long-bridges bench,
    0.2-0.4 mm, 2-4 sigma, on the joined targets). It is kept only where no set-up sees the target better.
    """
    sharp = {t for cents in setups.values() for t, c in cents.items() if not is_weak(c.flags)}
    return {k: {t: c for t, c in cents.items() if t not in sharp or not is_weak(c.flags)} for k, cents in setups.items()}


def corrected_side(label: str, setups: Mapping[int, Mapping[str, object]], model: FieldModel) -> CorrectedVisit:
    """Correct each set-up of a visit with its own field-model terms, then join them (see :func:`join_setups`).

    ``setups`` maps set-up number -> found centroids (``xyz_socs``, ``cov``, ``cos_incidence``, ``time_s``,
    ``flags``); a weak sighting of a target another set-up sees better is left out (:func:`without_weak_duplicates`).
    """
    obs, jac, devs, visits = {}, {}, {}, {}
    kept = without_weak_duplicates(setups)
    for k, cents in kept.items():
        v = visits[k] = visit_label(label, k)
        o, jc = corrected_observations(cents, model, v)
        obs[k] = o
        dv = family_deviations(cents, model, v, {t: x.xyz for t, x in o.items()})
        for t in cents:
            jac[(k, t)], devs[(k, t)] = jc[t], dv[t]
    return CorrectedVisit(weak_joins(join_setups(label, obs), kept), jac, devs, visits)


def weak_joins(join: SetupJoin, kept: Mapping[int, Mapping[str, Any]]) -> SetupJoin:
    """The join with the set-ups it joined through weak sightings named (:attr:`SetupJoin.weak`).

    ``kept``: each set-up's centroids as joined (:func:`without_weak_duplicates`: a shared target is there sharp from
    both sides or weak from both). A set-up sharing fewer than :data:`MIN_SHARED` sharp targets with those before it
    rests on weak ones, each millimetres off along its line of sight: the join's rotation is loose, and every value
    of that set-up carries it in its sigma (issue 40). A join through sharp targets that lie nearly on a line, far from
    the set-up (the long-bridges bench's 0.6 mm rows: pier targets 35-120 m away, spread 1.3-2 m, rotation sigma
    20-60 arcsec), is loose too; it is not flagged here: its sigma says it (``sigma_frame_mm``).
    """
    weak = {}
    for k, m in join.motions.items():
        shared = list(m.get("shared", ()))
        if not shared:
            continue
        poor = tuple(t for t in shared if t in kept.get(k, {}) and is_weak(getattr(kept[k][t], "flags", ())))
        if len(shared) - len(poor) < MIN_SHARED:
            weak[k] = poor
    return replace(join, weak=weak) if weak else join


def joined_displacements(baseline: CorrectedVisit, epoch: CorrectedVisit, groups: Mapping[str, str], *, model: FieldModel,
                         **options: object) -> EpochDisplacements:
    """Displacements of a visit against the baseline, either or both of several set-ups, with their budget.

    The displacement computation (:func:`lidar.displacement.compute_displacements`) runs on the joined
    positions; each displacement's variance is then split into the budget's terms through the joins' gains
    back to every corrected centroid (the correlations the shared motions bring included).
    """
    sides = {"baseline": baseline, "epoch": epoch}
    res = compute_displacements(baseline.join.observations(), epoch.join.observations(), groups,
                                **options)  # type: ignore[arg-type]
    sens = res.sensitivity
    if sens is None:
        return res
    weights = np.array([a[2] for a in model.range_walk.alternatives])
    out = []
    for d in res.displacements:
        if d.reflector not in sens.targets:
            out.append(d)
            continue
        i = sens.targets.index(d.reflector)
        t = _terms(sens.vertical[i], sens.inputs, sides, model, d.reflector, weights)
        own_cd, var_cd = _diagonal_variances(sens.vertical[i], sens.inputs, sides, d.reflector)
        normal2 = max(d.budget.get("frame", 0.0) ** 2 - (var_cd - own_cd), 0.0)
        budget = {"noise": math.sqrt(max(t["own"], 0.0)),
                  "frame": math.sqrt(max(t["total"] - t["own"], 0.0) + normal2),
                  "scale": math.sqrt(t["scale"]), "bias": math.sqrt(t["theta"] + t["alternatives"] + t["axes"]),
                  "drift": math.sqrt(t["drift"])}
        along_sigma = d.along_sigma_m
        if np.isfinite(d.along_m):
            ta = _terms(sens.along[i], sens.inputs, sides, model, d.reflector, weights)
            along_sigma = math.sqrt(max(ta["total"], 0.0) + ta["theta"] + ta["alternatives"] + ta["axes"] + ta["scale"]
                                    + ta["drift"])
        sigma = math.sqrt(sum(v ** 2 for v in budget.values()))
        out.append(replace(d, sigma_m=sigma, along_sigma_m=along_sigma, budget={k: float(v) for k, v in budget.items()}))
    return replace(res, displacements=tuple(out))


def _sighting_rows(row: np.ndarray, inputs, sides: Mapping[str, CorrectedVisit]) -> dict[str, np.ndarray]:
    """The row of one output over every corrected centroid of each side: (3 M_side,) through the join's gain."""
    out = {}
    for side, c in sides.items():
        g = np.zeros(3 * len(c.join.targets))
        for n, (s, t) in enumerate(inputs):
            if s == side and t in c.join.targets:
                k = c.join.targets.index(t)
                g[3 * k:3 * k + 3] = row[3 * n:3 * n + 3]
        out[side] = g @ c.join.gain
    return out


def _terms(row: np.ndarray, inputs, sides: Mapping[str, CorrectedVisit], model: FieldModel, target: str,
           weights: np.ndarray) -> dict:
    """Variance terms (m^2) of one output: centroid noise (own, total), range walk, scales, drifts."""
    h = _sighting_rows(row, inputs, sides)
    p = model.range_walk.covariance_m2.shape[0]
    j_theta = np.zeros(p)
    cov_axes = model.axes.covariance_arcsec2
    j_axes = np.zeros(cov_axes.shape[0])
    alt = np.zeros(weights.size)
    scale: dict[str, float] = {}
    drift: dict[str, np.ndarray] = {}
    own = total = 0.0
    for side, c in sides.items():
        for n, key in enumerate(c.join.sightings):
            hb = h[side][3 * n:3 * n + 3]
            v = float(hb @ c.join.sighting_cov[n] @ hb)
            total += v
            if key[1] == target:
                own += v
            cj = c.jacobians[key]
            j_theta += hb @ cj.d_theta
            j_axes += hb @ cj.d_axes
            label = c.visits[key[0]]
            scale[label] = scale.get(label, 0.0) + float(hb @ cj.d_scale)
            drift[label] = drift.get(label, np.zeros(3)) + hb @ cj.d_drift
            if weights.size:
                alt += c.deviations[key] @ hb
    cov_theta = model.range_walk.covariance_m2
    return {"own": own, "total": total,
            "theta": float(j_theta @ cov_theta @ j_theta) if p else 0.0,
            "axes": float(j_axes @ cov_axes @ j_axes),
            "scale": sum(js ** 2 * model.visit(lab).scale_sigma_ppm ** 2 for lab, js in scale.items()),
            "drift": sum(float(jd @ model.visit(lab).drift_cov @ jd) for lab, jd in drift.items()),
            "alternatives": float(family_spread2(alt, weights))}


def _diagonal_variances(row: np.ndarray, inputs, sides: Mapping[str, CorrectedVisit], target: str) -> tuple[float, float]:
    """(own, total) variance of one output as the displacement computation saw it: each joined target's 3x3 block."""
    own = total = 0.0
    for n, (side, t) in enumerate(inputs):
        c = sides[side].join
        if t not in c.targets:
            continue
        k = c.targets.index(t)
        g = row[3 * n:3 * n + 3]
        v = float(g @ c.covariance[3 * k:3 * k + 3, 3 * k:3 * k + 3] @ g)
        total += v
        if t == target:
            own += v
    return own, total


# ------------------------------------------------------------------------------------------ the QA trail
def join_tables(doc: Mapping) -> tuple[list[list[str]], list[list[str]]]:
    """The joint frame's QA trail as two tables (header row first): each set-up's motion, each shared sighting.

    ``doc`` is :meth:`SetupJoin.to_json` as stored with the epoch's displacements (``systematics["setups"]``).
    """
    motions = [["Set-up", "Shared targets", "Spread [m]", "Rotation σ [″]", "Translation σ [mm]",
                "RMS residual [mm]", "Joined"]]
    motions.append(["1", "–", "–", "–", "–", "–", "the joint frame"])
    for m in doc.get("motions", ()):
        rms = m.get("rms_mm")
        motions.append([str(m["setup"]), f"{len(m['shared'])}: {', '.join(m['shared'])}", f"{m['spread_m']:.2f}",
                        f"{m['rotation_sigma_arcsec']:.1f}", f"{m['translation_sigma_mm']:.2f}",
                        "–" if rms is None else f"{rms:.3f}", "yes"])
    for k, why in sorted(doc.get("refused", {}).items()):
        motions.append([str(k), "–", "–", "–", "–", "–", f"REFUSED: {why}"])
    residuals = [["Target", "Set-up", "Residual [mm]", "Normalised", "Used"]]
    for r in sorted(doc.get("residuals", ()), key=lambda r: (-float(r["normalised"]), r["reflector"], r["setup"])):
        residuals.append([r["reflector"], str(r["setup"]), f"{r['residual_mm']:.3f}", f"{r['normalised']:.2f}",
                          "left out" if r.get("left_out") else "yes"])
    return motions, residuals


def join_summary(doc: Mapping) -> str:
    """One line on how a visit's set-ups were joined (for the report's and the application's epoch details)."""
    joined, refused = doc.get("joined", []), doc.get("refused", {})
    text = f"{len(joined)} set-up(s) joined into set-up 1's frame through the targets they share " \
           f"(joint RMS normalised residual {float(doc.get('sigma0', float('nan'))):.2f})"
    if refused:
        text += f"; refused: {', '.join(f'set-up {k}' for k in sorted(refused))}"
    if doc.get("left_out"):
        text += "; left out of the join: " + ", ".join(f"{d['reflector']} from set-up {d['setup']}"
                                                        for d in doc["left_out"])
    return text

"""Reference-group vector math: vertical displacements independent of where the scanner stood.

For epoch k (dissertation eqs. 4.1-4.6, in our own notation):

* ``s_k`` = mean position of the stable reference targets (the same ones in both epochs);
* ``p_i,k = b_i,k - s_k`` for each measurement target;
* ``g`` = unit normal of the deck plane: the eigenvector of the smallest
  eigenvalue of the covariance of the measurement-group positions, oriented
  upwards (+z of a levelled scanner);
* ``h_i,k = g_k . p_i,k`` and ``u_i,k = h_i,k - h_i,1`` (positive up).

``normal_mode="reference"`` (default) computes ``g`` once at the baseline and
carries it into epoch k by the rotation that maps the baseline reference
targets onto epoch k's: the normal then cannot tilt with the deck's own
deflection, which otherwise leaks the targets' horizontal offsets into ``h``
(an asymmetric layout under a 10 mm sag can err by a millimetre).
``normal_mode="epoch"`` re-fits ``g_k`` in every epoch as in the dissertation.

Standard deviations are propagated from every centroid covariance of both
epochs through the whole computation (reference mean, normal, rotation) by a
numerical Jacobian.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

import numpy as np

from lidar.errors import InputError, ProcessingError
from lidar.rigid import fit_rigid

FLAG_MISSING = "missing"
FLAG_MISSING_AT_BASELINE = "missing_at_baseline"
FLAG_REFERENCE_MOVED = "reference_moved"
FLAG_REFERENCE_MISSING = "reference_missing"
FLAG_REFERENCE_INCONSISTENT = "reference_inconsistent"
FLAG_NORMAL_FROM_EPOCH = "normal_refitted_in_epoch"
FLAG_REFERENCE_AMBIGUOUS = "reference_change_ambiguous"


@dataclass(frozen=True)
class Observation:
    """A measured target position (scanner frame, metres) and its covariance (m^2)."""

    xyz: np.ndarray
    cov: np.ndarray


@dataclass(frozen=True)
class ReferenceCheck:
    """Stability of one reference target between the baseline and an epoch."""

    reflector: str
    median_change_m: float
    max_change_m: float
    moved: bool
    missing: bool
    suspect: bool = False  # one of two targets that may have moved; left out of the reference point


@dataclass(frozen=True)
class Displacement:
    """Vertical displacement of one measurement target against the baseline (positive up)."""

    reflector: str
    displacement_m: float
    sigma_m: float
    vertical_m: float
    baseline_vertical_m: float
    flags: tuple[str, ...] = ()

    @property
    def displacement_mm(self) -> float:
        return self.displacement_m * 1000.0

    @property
    def sigma_mm(self) -> float:
        return self.sigma_m * 1000.0


@dataclass(frozen=True, eq=False)
class EpochDisplacements:
    """All displacements of one epoch and how they were obtained."""

    displacements: tuple[Displacement, ...]
    reference_ids: tuple[str, ...]
    reference_checks: tuple[ReferenceCheck, ...]
    normal_socs: np.ndarray
    reference_point_socs: np.ndarray
    normal_mode: str
    flags: tuple[str, ...] = ()

    def of(self, reflector: str) -> Displacement:
        for d in self.displacements:
            if d.reflector == reflector:
                return d
        raise InputError(f"no displacement for reflector {reflector!r}")


def _as_obs(o) -> Observation:
    if isinstance(o, Observation):
        return o
    return Observation(np.asarray(o.xyz_socs, dtype=np.float64), np.asarray(o.cov, dtype=np.float64))


def deck_normal(xyz: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Unit normal of the best plane through points (smallest-eigenvalue eigenvector), oriented along ``up``."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) < 3:
        raise ProcessingError(f"the deck plane needs at least 3 measurement targets, got {len(xyz)}")
    c = xyz - xyz.mean(axis=0)
    w, v = np.linalg.eigh(c.T @ c / len(xyz))
    if w[1] < 1e-6:
        raise ProcessingError("the measurement targets are (nearly) collinear: they do not define a deck plane")
    g = v[:, 0]
    return g if g @ np.asarray(up) >= 0 else -g


def _pair_test(base, ep, a, b, tol_abs):
    ba, bb, ea, eb = base[a], base[b], ep[a], ep[b]
    d1, dk = ba.xyz - bb.xyz, ea.xyz - eb.xyz
    u1, uk = d1 / np.linalg.norm(d1), dk / np.linalg.norm(dk)
    var = u1 @ (ba.cov + bb.cov) @ u1 + uk @ (ea.cov + eb.cov) @ uk
    c = abs(np.linalg.norm(dk) - np.linalg.norm(d1))
    return c, c > max(tol_abs, 4.0 * np.sqrt(var))


def _consistency(base, ep, ids, measurement_ids) -> float:
    """How well one rigid motion explains the reference targets ``ids`` (RMS residual, metres).

    The motion fitted on the references must also leave the measurement targets
    where they were across the bridge: the deck moves vertically (and along the
    span with temperature) but not sideways. This tells a moved pier target from
    a spurious rotation about the other pier that its move resembles.
    """
    a = np.array([base[r].xyz for r in ids])
    b = np.array([ep[r].xyz for r in ids])
    rot, t = fit_rigid(a, b)
    res = [np.sum((a @ rot.T + t - b) ** 2, axis=1)]
    meas = [m for m in measurement_ids if m in base and m in ep]
    if len(meas) >= 3:
        mb = np.array([base[m].xyz for m in meas])
        me = np.array([ep[m].xyz for m in meas])
        c = mb - mb.mean(axis=0)
        _, vecs = np.linalg.eigh(c.T @ c)
        across = rot @ vecs[:, 1]  # horizontal, across the span (the middle principal axis)
        res.append(((mb @ rot.T + t - me) @ across) ** 2)
    return float(np.sqrt(np.mean(np.concatenate(res))))


def _loo_residual(base, ep, ids, k, tol_abs):
    """Residual of target ``k`` predicted by the rigid motion of the other reference targets, and its test."""
    others = [r for r in ids if r != k]
    rot, t = fit_rigid(np.array([base[r].xyz for r in others]), np.array([ep[r].xyz for r in others]))
    res = ep[k].xyz - (rot @ base[k].xyz + t)
    var = float(np.trace(ep[k].cov) + np.trace(rot @ base[k].cov @ rot.T)) * 2.0
    dist = float(np.linalg.norm(res))
    return dist, dist > max(tol_abs, 4.0 * np.sqrt(var))


def check_references(baseline: Mapping[str, Observation], epoch: Mapping[str, Observation],
                     reference_ids: Sequence[str], *, tolerance_m: Optional[float] = None,
                     measurement_ids: Sequence[str] = ()) -> tuple[tuple[ReferenceCheck, ...], tuple[str, ...], tuple[str, ...]]:
    """Find reference targets that moved (or were replaced) since the baseline.

    With four or more reference targets, the one whose removal leaves the
    others most consistent with one rigid motion is predicted from them
    (leave-one-out); if it misses by more than ``max(tolerance, 4 sigma)`` it
    is removed, and the test repeats while four or more remain. With three, the pairwise distances decide (a target whose two
    distances changed while the third did not). Changes that cannot be pinned
    on one target flag the epoch ``reference_inconsistent``.

    Returns
    -------
    checks : per reference target (``median_change_m`` and ``max_change_m`` are
        the changes of its distances to the other reference targets)
    stable : ids usable for the reference point
    flags : epoch-level flags
    """
    present = [r for r in reference_ids if r in baseline and r in epoch]
    tol_abs = 0.001 if tolerance_m is None else float(tolerance_m)
    alive = list(present)
    moved: set[str] = set()
    ambiguous: set[str] = set()
    while len(alive) >= 4:
        # The outlier is the target whose removal leaves the others most consistent with one rigid
        # motion (its own residual alone can point at an innocent one whose fit it distorted).
        scores = sorted((_consistency(baseline, epoch, [r for r in alive if r != k], measurement_ids), k)
                        for k in alive)
        worst = scores[0][1]
        dist, bad = _loo_residual(baseline, epoch, alive, worst, tol_abs)
        if not bad:
            break
        runner_up = scores[1][1]
        if scores[1][0] < 1.5 * max(scores[0][0], 1e-5) and _loo_residual(baseline, epoch, alive, runner_up,
                                                                           tol_abs)[1]:
            # Two targets explain the change equally well (e.g. a vertical move of one of two targets
            # on a pier looks like a rotation about the other pier): trust neither.
            ambiguous.update((worst, runner_up))
            alive = [r for r in alive if r not in (worst, runner_up)]
            break
        moved.add(worst)
        alive.remove(worst)
    pair_bad = {(a, b): _pair_test(baseline, epoch, a, b, tol_abs) for i, a in enumerate(alive)
                for b in alive[i + 1:]}
    if len(alive) == 3:
        counts = {r: sum(1 for (a, b), (_, bad) in pair_bad.items() if bad and r in (a, b)) for r in alive}
        culprits = [r for r, c in counts.items() if c == 2]
        if len(culprits) == 1 and sum(bad for _, bad in pair_bad.values()) == 2:
            moved.add(culprits[0])
            alive.remove(culprits[0])
            pair_bad = {k: v for k, v in pair_bad.items() if culprits[0] not in k}
    flags = []
    if any(bad for _, bad in pair_bad.values()):
        flags.append(FLAG_REFERENCE_INCONSISTENT)
    checks = []
    for r in reference_ids:
        if r not in present:
            checks.append(ReferenceCheck(r, float("nan"), float("nan"), False, True))
            continue
        ch = [_pair_test(baseline, epoch, r, o, tol_abs)[0] for o in present if o != r] or [float("nan")]
        checks.append(ReferenceCheck(r, float(np.median(ch)), float(np.max(ch)), r in moved, False,
                                     r in ambiguous))
    if any(c.missing for c in checks):
        flags.append(FLAG_REFERENCE_MISSING)
    if moved:
        flags.append(FLAG_REFERENCE_MOVED)
    if ambiguous:
        flags.append(FLAG_REFERENCE_AMBIGUOUS)
    return tuple(checks), tuple(alive), tuple(flags)


def _vertical_positions(base: dict, ep: dict, refs, meas_base, meas, mode: str, w_ref: np.ndarray,
                        w_rot: np.ndarray):
    """h at baseline and epoch for ``meas`` ids, given position dicts id -> (3,) array.

    The reference point is the same weighted mean of the same targets in both
    epochs (weights fixed beforehand), so it is the same physical point.
    """
    b_ref = np.array([base[r] for r in refs])
    e_ref = np.array([ep[r] for r in refs])
    s1 = w_ref @ b_ref
    sk = w_ref @ e_ref
    if mode == "reference":
        g1 = deck_normal(np.array([base[m] for m in meas_base]))
        rot, _ = fit_rigid(b_ref, e_ref, weights=w_rot)
        gk = rot @ g1
    else:
        gk = deck_normal(np.array([ep[m] for m in meas]))
        g1 = deck_normal(np.array([base[m] for m in meas]))
    h1 = np.array([g1 @ (base[m] - s1) for m in meas])
    hk = np.array([gk @ (ep[m] - sk) for m in meas])
    return h1, hk, gk, sk


def reference_weights(base: Mapping[str, Observation], ep: Mapping[str, Observation], refs: Sequence[str],
                      up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights of the reference targets: for the reference point (inverse vertical variance over both
    epochs) and for the rotation fit (inverse total variance). Each set sums to 1."""
    var_up = np.array([up @ (base[r].cov + ep[r].cov) @ up for r in refs])
    var_all = np.array([np.trace(base[r].cov + ep[r].cov) for r in refs])
    w_ref = 1.0 / np.maximum(var_up, 1e-14)
    w_rot = 1.0 / np.maximum(var_all, 1e-14)
    return w_ref / w_ref.sum(), w_rot / w_rot.sum()


def compute_displacements(baseline: Mapping[str, object], epoch: Mapping[str, object], groups: Mapping[str, str], *,
                          normal_mode: str = "reference", moved_tolerance_m: Optional[float] = None,
                          weighted: bool = True) -> EpochDisplacements:
    """Vertical displacements of an epoch against the baseline epoch.

    Parameters
    ----------
    baseline, epoch : mapping reflector id -> observation
        Found targets with ``xyz_socs`` (3,) metres and ``cov`` (3, 3) m^2
        (e.g. :class:`lidar.centroid.TargetCentroid`), each in its own epoch's
        scanner frame.
    groups : mapping reflector id -> "reference" | "measurement"
    normal_mode : {"reference", "epoch"}, keyword-only
        How the deck normal of the epoch is obtained (see the module notes).
    moved_tolerance_m : float, optional, keyword-only
        Smallest change of a reference distance taken as movement. Default 1 mm
        (or 4 sigma, whichever is larger).
    weighted : bool, keyword-only
        Weight the reference targets by their precision (the same weights in
        both epochs). False gives the plain mean of the dissertation. Default True.

    Returns
    -------
    EpochDisplacements
    """
    if normal_mode not in ("reference", "epoch"):
        raise InputError(f"normal_mode must be 'reference' or 'epoch', not {normal_mode!r}")
    base = {k: _as_obs(v) for k, v in baseline.items()}
    ep = {k: _as_obs(v) for k, v in epoch.items()}
    for name, d in (("baseline", base), ("epoch", ep)):
        for k, o in d.items():
            if o.xyz.shape != (3,) or not np.all(np.isfinite(o.xyz)) or o.cov.shape != (3, 3):
                raise InputError(f"{name} observation of {k!r} must be a finite (3,) position with a (3, 3) covariance")
    ref_ids = [r for r, g in groups.items() if g == "reference"]
    meas_ids = [m for m, g in groups.items() if g == "measurement"]
    checks, stable, flags = check_references(base, ep, ref_ids, tolerance_m=moved_tolerance_m,
                                             measurement_ids=meas_ids)
    flags = list(flags)
    if not stable:
        raise ProcessingError("no reference target was measured in both this epoch and the baseline; "
                              "displacements cannot be referred to the piers")
    meas_base = [m for m in meas_ids if m in base]
    meas = [m for m in meas_base if m in ep]
    if len(meas_base) < 3:
        raise ProcessingError(f"the baseline has only {len(meas_base)} measurement targets; 3 are needed for the deck plane")
    mode = normal_mode
    if mode == "reference":
        ref_xyz = np.array([base[r].xyz for r in stable])
        spread = np.linalg.svd(ref_xyz - ref_xyz.mean(axis=0), compute_uv=False) if len(stable) >= 3 else [0, 0, 0]
        if len(stable) < 3 or spread[1] < 0.05 * max(spread[0], 1e-9):
            mode = "epoch"
            flags.append(FLAG_NORMAL_FROM_EPOCH)
    if mode == "epoch" and len(meas) < 3:
        raise ProcessingError(f"only {len(meas)} measurement targets in this epoch; 3 are needed for the deck plane")
    up = deck_normal(np.array([base[m].xyz for m in meas_base]))
    w_ref, w_rot = reference_weights(base, ep, stable, up) if weighted else (
        np.full(len(stable), 1.0 / len(stable)), np.full(len(stable), 1.0 / len(stable)))
    involved_b = sorted(set(stable) | set(meas_base))
    involved_e = sorted(set(stable) | set(meas))
    x0 = np.concatenate([base[k].xyz for k in involved_b] + [ep[k].xyz for k in involved_e])
    nb = len(involved_b)

    def f(x):
        xb = {k: x[3 * i:3 * i + 3] for i, k in enumerate(involved_b)}
        xe = {k: x[3 * (nb + i):3 * (nb + i) + 3] for i, k in enumerate(involved_e)}
        return _vertical_positions(xb, xe, stable, meas_base, meas, mode, w_ref, w_rot)

    h1, hk, gk, sk = f(x0)
    u0 = hk - h1
    step = 1e-6
    jac = np.empty((len(meas), x0.size))
    for j in range(x0.size):
        xp, xm = x0.copy(), x0.copy()
        xp[j] += step
        xm[j] -= step
        hp1, hpk = f(xp)[:2]
        hm1, hmk = f(xm)[:2]
        jac[:, j] = ((hpk - hp1) - (hmk - hm1)) / (2 * step)
    cov = np.zeros((x0.size, x0.size))
    for i, k in enumerate(involved_b):
        cov[3 * i:3 * i + 3, 3 * i:3 * i + 3] = base[k].cov
    for i, k in enumerate(involved_e):
        j = nb + i
        cov[3 * j:3 * j + 3, 3 * j:3 * j + 3] = ep[k].cov
    sigma = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0))
    out = []
    for m in meas_ids:
        if m in meas:
            i = meas.index(m)
            out.append(Displacement(m, float(u0[i]), float(sigma[i]), float(hk[i]), float(h1[i])))
        else:
            flag = FLAG_MISSING_AT_BASELINE if m not in base else FLAG_MISSING
            out.append(Displacement(m, float("nan"), float("nan"), float("nan"), float("nan"), (flag,)))
    return EpochDisplacements(tuple(out), tuple(stable), checks, gk, sk, mode, tuple(flags))

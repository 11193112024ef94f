"""Reference-group vector math: vertical displacements independent of where the scanner stood.

For epoch k (dissertation eqs. 4.1-4.6, in our own notation):

* ``s_k`` = mean position of the stable reference targets (the same ones in both epochs);
* ``p_i,k = b_i,k - s_k`` for each measurement target;
* ``g`` = unit normal of the deck plane: the eigenvector of the smallest
  eigenvalue of the covariance of the measurement-group positions, oriented
  upwards (+z of a levelled scanner);
* ``h_i,k = g_k . p_i,k`` and ``u_i,k = h_i,k - h_i,1`` (positive up).

Which normal ``g_k``:

* ``normal_mode="reference"`` computes ``g`` once at the baseline and carries
  it into epoch k by the motion between the two scanner frames: the normal
  then cannot tilt with the deck's own deflection, which otherwise leaks the
  targets' horizontal offsets into ``h`` (an asymmetric layout under a 10 mm
  sag can err by a millimetre). The motion is fitted on the reference targets
  and on the deck targets' across-span coordinate (a deck does not move
  sideways; :mod:`lidar.reference_motion`), so two pier targets a metre apart
  are enough even on a 60 m span.
* ``normal_mode="epoch"`` re-fits ``g_k`` in every epoch as in the dissertation.
* ``normal_mode="auto"`` (default) propagates both normals' uncertainties; when
  they agree within their noise (chi-square at 95 %) they are combined by
  inverse covariance, otherwise the deck has deformed and the carried normal
  is kept. ``normal_refitted_in_epoch`` (information) says when the epoch fit
  had the larger share.

Standard deviations are propagated from every centroid covariance of both
epochs through the whole computation (reference mean, normal, rotation) by a
numerical Jacobian.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError, ProcessingError
from common.flags import (
    FLAG_MISSING,
    FLAG_MISSING_AT_BASELINE,
    FLAG_NORMAL_FROM_EPOCH,
    FLAG_REFERENCE_AMBIGUOUS,
    FLAG_REFERENCE_GEOMETRY_WEAK,
    FLAG_REFERENCE_INCONSISTENT,
    FLAG_REFERENCE_MISSING,
    FLAG_REFERENCE_MOVED,
)
from common.rigid import fit_rigid
from lidar.displacement_result import Displacement, EpochDisplacements, Observation, ReferenceCheck, Sensitivity
from lidar.pier_moves import resolve_ambiguous_move, span_coordinates, verify_single_move
from lidar.reference_motion import across_axis, fit_reference_motion, rotation_covariance

#: 95 % quantile of chi-square with 2 degrees of freedom: the two deck normals agree within their noise.
CHI2_2DOF_95 = 5.991
#: How the epoch's deck normal is obtained (see the module notes).
NORMAL_MODES = ("auto", "reference", "epoch")


def _as_obs(o) -> Observation:
    if isinstance(o, Observation):
        return o
    return Observation(np.asarray(o.xyz_socs, dtype=np.float64), np.asarray(o.cov, dtype=np.float64))


def deck_normal(xyz: np.ndarray, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
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
    motion = fit_rigid(a, b)
    rot, t = motion.rotation, motion.translation
    res = [np.sum((motion.apply(a) - b) ** 2, axis=1)]
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
    motion = fit_rigid(np.array([base[r].xyz for r in others]), np.array([ep[r].xyz for r in others]))
    rot = motion.rotation
    res = ep[k].xyz - motion.apply(base[k].xyz)
    var = float(np.trace(ep[k].cov) + np.trace(rot @ base[k].cov @ rot.T)) * 2.0
    dist = float(np.linalg.norm(res))
    return dist, dist > max(tol_abs, 4.0 * np.sqrt(var))


def check_references(baseline: Mapping[str, Observation], epoch: Mapping[str, Observation],
                     reference_ids: Sequence[str], *, tolerance_m: float | None = None,
                     measurement_ids: Sequence[str] = ()
                     ) -> tuple[tuple[ReferenceCheck, ...], tuple[str, ...], tuple[str, ...]]:
    """Find reference targets that moved (or were replaced) since the baseline.

    With four or more reference targets, the one whose removal leaves the
    others most consistent with one rigid motion is predicted from them
    (leave-one-out); if it misses by more than ``max(tolerance, 4 sigma)`` it
    is removed, and the test repeats while four or more remain. With three, the pairwise distances decide (a target
    whose two
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


@dataclass(frozen=True)
class MotionWeights:
    """Fixed weights of the frame-motion fit (computed once from the covariances)."""

    ref_var: np.ndarray  # (n_ref,) per-coordinate variance of each reference target's difference, m^2
    deck_ids: tuple[str, ...]  # deck targets found in both epochs
    deck_var: np.ndarray  # (n_deck,) across-span variance of their differences, m^2
    across: np.ndarray | None  # unit across-span axis in the baseline frame, or None


def _motion(base: dict, ep: dict, refs, mw: MotionWeights) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) with ``epoch ~= R base + t``, from the reference targets and the deck's across-span stability."""
    b_ref = np.array([base[r] for r in refs])
    e_ref = np.array([ep[r] for r in refs])
    if mw.across is None or not mw.deck_ids:
        return fit_reference_motion(b_ref, e_ref, mw.ref_var)
    return fit_reference_motion(b_ref, e_ref, mw.ref_var, deck_base=np.array([base[m] for m in mw.deck_ids]),
                                deck_epoch=np.array([ep[m] for m in mw.deck_ids]), deck_var_across=mw.deck_var,
                                across_base=mw.across)


def _normals(base: dict, ep: dict, refs, meas_base, meas, mw: MotionWeights):
    """(g1, g_ref, g_epoch, motion): the deck normal of the baseline, carried, re-fitted, and the frame motion.

    The baseline deck normal, carried into the epoch by the frame motion (None with fewer than
    three reference targets), and re-fitted on the epoch's own deck targets (None with fewer than three);
    the motion ``(R, t)`` (None with fewer than three reference targets).
    """
    g1 = deck_normal(np.array([base[m] for m in meas_base]))
    motion = _motion(base, ep, refs, mw) if len(refs) >= 3 else None
    g_ref = motion[0] @ g1 if motion is not None else None
    g_ep = deck_normal(np.array([ep[m] for m in meas])) if len(meas) >= 3 else None
    return g1, g_ref, g_ep, motion


def _vertical_positions(base: dict, ep: dict, refs, meas_base, meas, mode: str, w_ref: np.ndarray,
                        mw: MotionWeights, gain: np.ndarray | None = None, along_axis: np.ndarray | None = None):
    """(h1, hk, gk, sk, along) for ``meas`` ids, given position dicts id -> (3,) array.

    The reference point is the same weighted mean of the same targets in both
    epochs (weights fixed beforehand), so it is the same physical point. In
    ``auto`` mode the epoch normal is ``g_ref + gain (g_epoch - g_ref)``,
    normalised, with the 3x3 ``gain`` fixed beforehand by :func:`normal_gain`. ``along`` is each
    target's movement along ``along_axis`` (baseline frame) through the frame motion (None without one).
    """
    b_ref = np.array([base[r] for r in refs])
    e_ref = np.array([ep[r] for r in refs])
    s1 = w_ref @ b_ref
    sk = w_ref @ e_ref
    motion = None
    if mode == "epoch":
        g1 = deck_normal(np.array([base[m] for m in meas]))
        gk = deck_normal(np.array([ep[m] for m in meas]))
        if along_axis is not None and len(refs) >= 3:
            motion = _motion(base, ep, refs, mw)
    else:
        g1, g_ref, g_ep, motion = _normals(base, ep, refs, meas_base, meas, mw)
        if g_ref is None:
            raise ProcessingError("the deck normal cannot be carried into the epoch: fewer than three reference "
                                  "targets were found in both epochs")
        gk = g_ref
        if mode == "auto" and gain is not None and g_ep is not None:
            gk = g_ref + gain @ (g_ep - g_ref)
            gk = gk / np.linalg.norm(gk)
    h1 = np.array([g1 @ (base[m] - s1) for m in meas])
    hk = np.array([gk @ (ep[m] - sk) for m in meas])
    along = None
    if motion is not None and along_axis is not None:
        rot, t = motion
        along = np.array([along_axis @ (rot.T @ (ep[m] - t) - base[m]) for m in meas])
    return h1, hk, gk, sk, along


def _tangent_basis(g: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal basis of the plane perpendicular to unit vector ``g``."""
    a = np.array([1.0, 0.0, 0.0]) if abs(g[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(g, a)
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, np.cross(g, e1)])


def normal_gain(normals: Callable[[np.ndarray], Any], x0: np.ndarray, cov: np.ndarray, step: float = 1e-6, *,
                expected: bool = False, bending_tilt: np.ndarray | None = None
                ) -> tuple[np.ndarray | None, np.ndarray, float]:
    """How far to move from the carried normal toward the epoch's own fit, by their uncertainties.

    ``normals(x) -> (g_ref, g_epoch)``. Both normals' covariances are
    propagated from the observations' (numerical Jacobian). When their
    difference ``d`` is larger than that noise explains (chi-square test at
    95 %), the deck's own deformation tilts the epoch fit and the carried
    normal is kept alone. Otherwise both are combined by their inverse
    covariances in the plane perpendicular to ``g_ref`` (in each direction the
    better determined normal wins), and ``d`` itself bounds the deformation the
    test could not see, for the sigmas.

    ``expected=True`` gives the sigmas expected before the epoch is measured (the
    station advisor): no test, and ``d d^T`` replaced by its expectation under
    noise alone, the sum of the two normals' covariances.

    ``bending_tilt`` (:func:`bending_tilt`): the tilt the deck's own bending gives the epoch fit. Where the
    combination's noise and that tilt's share in it would err more than the carried normal alone (their mean
    squares), the carried normal is kept alone: the difference
    test cannot see such a tilt when noise happens to cancel part of it (the lab desk under its first
    load: a 0.36 mrad tilt across the desk seen as 0.13, 0.27 mm on the targets at 2.4 sigma).

    Returns
    -------
    gain : (3, 3) array or None
        ``g = g_ref + gain (g_epoch - g_ref)``; None when there is no epoch fit.
    bias_cov : (3, 3) array
        Covariance (rad^2) of the bias the combined normal still carries, for the sigmas.
    weight_epoch : float
        Share of the epoch fit in the combination (0 = carried normal only, 1 = epoch fit only).
    """
    g_ref, g_ep = normals(x0)
    if g_ep is None or g_ref is None:
        return None, np.zeros((3, 3)), 0.0 if g_ep is None else 1.0
    jr = np.empty((3, x0.size))
    je = np.empty((3, x0.size))
    for j in range(x0.size):
        xp, xm = x0.copy(), x0.copy()
        xp[j] += step
        xm[j] -= step
        rp, ep_ = normals(xp)
        rm, em = normals(xm)
        jr[:, j] = (rp - rm) / (2 * step)
        je[:, j] = (ep_ - em) / (2 * step)
    e = _tangent_basis(g_ref)
    cr = e @ jr @ cov @ jr.T @ e.T
    ce = e @ je @ cov @ je.T @ e.T
    d = e @ (g_ep - g_ref)
    reg = 1e-18 * np.eye(2)
    chi2 = float(d @ np.linalg.solve(cr + ce + reg, d))
    if chi2 > CHI2_2DOF_95 and not expected:
        # The two normals disagree beyond their noise: the deck's own deformation tilts the epoch fit.
        # Keep the carried normal, and let the sigmas carry what its own noise may still hide.
        return np.zeros((3, 3)), np.zeros((3, 3)), 0.0
    wr = np.linalg.inv(cr + reg)
    we = np.linalg.inv(ce + reg)
    k2 = np.linalg.solve(wr + we, we)
    if bending_tilt is not None and not expected:
        t = k2 @ e @ np.asarray(bending_tilt, dtype=np.float64)  # what the bending would tilt the combination by
        rest = np.eye(2) - k2
        if np.trace(rest @ cr @ rest.T + k2 @ ce @ k2.T) + t @ t > np.trace(cr):
            return np.zeros((3, 3)), np.zeros((3, 3)), 0.0  # the carried normal alone is the better one
    gain = e.T @ k2 @ e
    # a deformation too small to be detected may still be there: at most the test's threshold
    bias = cr + ce if expected else np.outer(d, d)
    bias_cov = e.T @ (k2 @ bias @ k2.T) @ e
    return gain, bias_cov, float(np.trace(k2) / 2.0)


def chi2_95(dof: int) -> float:
    """The chi-square distribution's 95 % quantile for ``dof`` degrees of freedom.

    Exact (to three decimals) up to 10; beyond, the Wilson-Hilferty cube, within 0.2 % there (scipy.stats
    is not imported for it: it costs every campaign command start-up time).
    """
    if dof < 1:
        raise InputError(f"a chi-square quantile needs at least one degree of freedom, not {dof}")
    if dof <= len(_CHI2_95):
        return _CHI2_95[dof - 1]
    a = 2.0 / (9.0 * dof)
    return float(dof * (1.0 - a + 1.6448536 * np.sqrt(a)) ** 3)


_CHI2_95 = (3.841, 5.991, 7.815, 9.488, 11.070, 12.592, 14.067, 15.507, 16.919, 18.307)


@dataclass(frozen=True)
class _Bend:
    ids: list
    residual: np.ndarray  # (n,) along the epoch's deck normal, m
    weight: np.ndarray  # (n, n) pseudo-inverse of its covariance (rank n - 3)
    normal: np.ndarray  # the epoch's deck normal
    epoch_xyz: np.ndarray  # (n, 3)
    chi2: float
    dof: int


def _bend(base: Mapping[str, Observation], ep: Mapping[str, Observation], meas: Sequence[str],
          step: float = 1e-7) -> _Bend | None:
    """The deck targets' bending between the baseline and the epoch, with its chi-square against its noise.

    The deck targets of the epoch against those of the baseline carried onto them by their own best rigid
    motion: what is left along the deck's normal is the part of the deck's vertical movement that no plane
    describes (a sag, a twist), free of the frame's motion, which a rigid fit takes whole. Its noise is
    propagated from the centroids' covariances (numerical Jacobian); a tilt and a height of the deck's
    plane are absorbed by the fit, so it has ``n - 3`` degrees of freedom. None with fewer than four targets.
    """
    ids = [m for m in meas if m in base and m in ep]
    n = len(ids)
    if n < 4:
        return None
    x0 = np.concatenate([base[m].xyz for m in ids] + [ep[m].xyz for m in ids])
    cov = np.zeros((6 * n, 6 * n))
    for i, m in enumerate(ids):
        cov[3 * i:3 * i + 3, 3 * i:3 * i + 3] = base[m].cov
        cov[3 * (n + i):3 * (n + i) + 3, 3 * (n + i):3 * (n + i) + 3] = ep[m].cov
    e_xyz = x0[3 * n:].reshape(n, 3)
    g = deck_normal(e_xyz)

    def residual(x: np.ndarray) -> np.ndarray:
        b, e = x[:3 * n].reshape(n, 3), x[3 * n:].reshape(n, 3)
        return (e - fit_rigid(b, e).apply(b)) @ g

    r0 = residual(x0)
    jac = np.empty((n, x0.size))
    for j in range(x0.size):
        xp, xm = x0.copy(), x0.copy()
        xp[j] += step
        xm[j] -= step
        jac[:, j] = (residual(xp) - residual(xm)) / (2 * step)
    vals, vecs = np.linalg.eigh(jac @ cov @ jac.T)
    dof = n - 3
    vals, vecs = vals[-dof:], vecs[:, -dof:]  # the three smallest belong to the plane the fit absorbs
    if vals[0] <= 0.0:
        return None
    weight = (vecs / vals) @ vecs.T
    return _Bend(ids, r0, weight, g, e_xyz, float(r0 @ weight @ r0), dof)


#: Relative singular value below which a bending shape's amplitude counts as undetermined (:func:`bending_tilt`).
BENDING_RCOND = 1e-2


def bending_tilt(base: Mapping[str, Observation], ep: Mapping[str, Observation], meas: Sequence[str],
                 refs: Sequence[str]) -> np.ndarray | None:
    """The tilt (a 3-vector across the deck's normal, rad) the deck's own bending gives its fitted plane.

    None when the deck did not bend beyond its noise (95 %), when the tilt is not beyond its own noise (95 %,
    propagated from the bending's), or when the bending's shape cannot be placed between piers. A sag is smooth and zero at the piers: each girder line's bending is taken as the
    supported span's first shape (``sin(pi xi)``, ``xi`` from pier to pier, :func:`lidar.pier_moves.span_coordinates`),
    one amplitude for the deck and each girder line's departure from it fitted (least norm) to the bending a
    rigid fit of the deck targets leaves, and the tilt is the plane those shapes give at the targets. On a
    symmetric layout a sag tilts nothing; where the girder lines' targets sit at different places along the
    span (the dissertation's lab desk) the same sag tilts the plane across the span.
    """
    bend = _bend(base, ep, meas)
    if bend is None or bend.chi2 <= chi2_95(bend.dof):
        return None
    geo = span_coordinates(base, {**{r: "reference" for r in refs}, **{m: "measurement" for m in bend.ids}},
                           bend.ids)
    if geo is None:
        return None
    xi, lines = geo
    sag = np.sin(np.pi * xi)
    # one sag for the deck, and each further line's own departure from it (0 where no bending tells it: a line
    # whose targets all sit alike along the span shows a departure only as a plane, which the fit absorbs)
    shapes = np.column_stack([sag] + [np.where(lines == k, sag, 0.0) for k in range(1, int(lines.max()) + 1)])
    e = _tangent_basis(bend.normal)
    c = bend.epoch_xyz - bend.epoch_xyz.mean(axis=0)
    plane = np.column_stack([np.ones(len(c)), c @ e[0], c @ e[1]])
    to_plane = np.linalg.pinv(plane)
    left = shapes - plane @ (to_plane @ shapes)  # what the rigid fit leaves of each shape
    vals, vecs = np.linalg.eigh(bend.weight)
    root = (vecs * np.sqrt(np.clip(vals, 0.0, None))).T
    # an amplitude the bending fixes a hundred times less well than the best one is left at 0 (least norm): two
    # targets of a line at nearly one place along the span would otherwise turn noise into metres of departure
    to_amp = np.linalg.pinv(root @ left, rcond=BENDING_RCOND) @ root
    to_tilt = -e.T @ (to_plane @ shapes)[1:] @ to_amp  # (3, n); the plane's slopes turn its normal the other way
    tilt = to_tilt @ bend.residual
    # the tilt against its own noise (the bending's, through the same map), in the plane across the normal
    t = e @ tilt
    lam, axes = np.linalg.eigh(e @ to_tilt @ np.linalg.pinv(bend.weight, hermitian=True) @ to_tilt.T @ e.T)
    keep = lam > 1e-9 * max(float(lam[-1]), 1e-30)
    chi2 = float(np.sum((axes[:, keep].T @ t) ** 2 / lam[keep]))
    return tilt if keep.any() and chi2 > chi2_95(int(np.count_nonzero(keep))) else None


def reference_weights(base: Mapping[str, Observation], ep: Mapping[str, Observation], refs: Sequence[str],
                      up: np.ndarray) -> np.ndarray:
    """Weights of the reference targets for the reference point.

    Inverse vertical variance over both epochs, summing to 1 (the frame-motion fit weighs them by
    :func:`motion_weights`).
    """
    var_up = np.array([up @ (base[r].cov + ep[r].cov) @ up for r in refs])
    w_ref = 1.0 / np.maximum(var_up, 1e-14)
    return w_ref / w_ref.sum()


def motion_weights(base: Mapping[str, Observation], ep: Mapping[str, Observation], refs: Sequence[str],
                   meas: Sequence[str], up: np.ndarray, weighted: bool) -> MotionWeights:
    """Variances for the frame-motion fit.

    Each reference target's (isotropic) and each deck target's across the span. ``weighted=False`` weighs the
    reference targets equally (the dissertation's plain mean).
    """
    if not weighted:
        ref_var = np.full(len(refs), 1e-8)
    else:
        ref_var = np.array([np.trace(base[r].cov + ep[r].cov) / 3.0 for r in refs])
    across = across_axis(np.array([base[m].xyz for m in meas]), up) if len(meas) >= 2 else None
    if across is None:
        return MotionWeights(ref_var, (), np.zeros(0), None)
    deck_var = np.array([across @ (base[m].cov + ep[m].cov) @ across for m in meas])
    return MotionWeights(ref_var, tuple(meas), deck_var, across)


def compute_displacements(baseline: Mapping[str, object], epoch: Mapping[str, object], groups: Mapping[str, str], *,
                          normal_mode: str = "auto", moved_tolerance_m: float | None = None,
                          weighted: bool = True, expected_sigmas: bool = False,
                          first_reference: str | None = None) -> EpochDisplacements:
    """Vertical displacements of an epoch against the baseline epoch.

    Parameters
    ----------
    baseline, epoch : mapping reflector id -> observation
        Found targets with ``xyz_socs`` (3,) metres and ``cov`` (3, 3) m^2
        (e.g. :class:`lidar.centroid.TargetCentroid`), each in its own epoch's
        scanner frame.
    groups : mapping reflector id -> "reference" | "measurement"
    normal_mode : {"auto", "reference", "epoch"}, keyword-only
        How the deck normal of the epoch is obtained (see the module notes).
        Default ``auto``: the carried and the re-fitted normals combined by
        their propagated uncertainties.
    moved_tolerance_m : float, optional, keyword-only
        Smallest change of a reference distance taken as movement. Default 1 mm
        (or 4 sigma, whichever is larger).
    weighted : bool, keyword-only
        Weight the reference targets by their precision (the same weights in
        both epochs). False gives the plain mean of the dissertation. Default True.
    expected_sigmas : bool, keyword-only
        The sigmas expected before the epoch is measured, for planning (see
        :func:`normal_gain`); the displacements themselves are unchanged. Default False.
    first_reference : str, optional, keyword-only
        A reference target on the first pier: the along-span movements are positive away from it.
        Default: the first reference target of ``groups`` found in both epochs.

    Returns
    -------
    EpochDisplacements
    """
    if normal_mode not in NORMAL_MODES:
        raise InputError(f"normal_mode must be one of {', '.join(NORMAL_MODES)}, not {normal_mode!r}")
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

    def solve(stable_ids, checks_, flags_):
        return _solve(base, ep, meas_ids, list(stable_ids), checks_, list(flags_), normal_mode, weighted,
                      expected_sigmas, first_reference if first_reference is not None else
                      next((r for r in ref_ids if r in base and r in ep), None))

    result = solve(stable, checks, flags)
    # A moved pier target: the deck's shape (zero at the supports) tells which one it was.
    if FLAG_REFERENCE_AMBIGUOUS in flags:
        result = resolve_ambiguous_move(result, base, groups, solve,
                                        lambda ids: _consistency(base, ep, ids, meas_ids))
    elif FLAG_REFERENCE_MOVED in flags:
        result = verify_single_move(result, base, groups, solve,
                                    lambda ids: _consistency(base, ep, ids, meas_ids))
    return result


def _solve(base: dict, ep: dict, meas_ids: list, stable: list, checks, flags: list, normal_mode: str,
           weighted: bool, expected_sigmas: bool = False, first_reference: str | None = None
           ) -> EpochDisplacements:
    """Displacements of ``meas_ids`` with the reference point and frame motion from ``stable``."""
    if not stable:
        raise ProcessingError("no reference target was measured in both this epoch and the baseline; "
                              "displacements cannot be referred to the piers")
    meas_base = [m for m in meas_ids if m in base]
    meas = [m for m in meas_base if m in ep]
    if len(meas_base) < 3:
        raise ProcessingError(f"the baseline has only {len(meas_base)} measurement targets; 3 are needed for the deck plane")
    mode = normal_mode
    if mode != "epoch" and len(stable) < 3:  # no rotation from fewer than three reference targets
        mode = "epoch"
        flags.append(FLAG_NORMAL_FROM_EPOCH)
    if mode == "epoch" and len(meas) < 3:
        raise ProcessingError(f"only {len(meas)} measurement targets in this epoch; 3 are needed for the deck plane")
    up = deck_normal(np.array([base[m].xyz for m in meas_base]))
    w_ref = reference_weights(base, ep, stable, up) if weighted else np.full(len(stable), 1.0 / len(stable))
    mw = motion_weights(base, ep, stable, meas, up, weighted)
    weak = _weak_geometry(base, stable, meas_base, meas, up, mw) if mode != "epoch" else None
    if weak:
        flags.append(weak)
    involved_b = sorted(set(stable) | set(meas_base))
    involved_e = sorted(set(stable) | set(meas))
    x0 = np.concatenate([base[k].xyz for k in involved_b] + [ep[k].xyz for k in involved_e])
    nb = len(involved_b)

    def split(x):
        xb = {k: x[3 * i:3 * i + 3] for i, k in enumerate(involved_b)}
        xe = {k: x[3 * (nb + i):3 * (nb + i) + 3] for i, k in enumerate(involved_e)}
        return xb, xe

    cov = np.zeros((x0.size, x0.size))
    for i, k in enumerate(involved_b):
        cov[3 * i:3 * i + 3, 3 * i:3 * i + 3] = base[k].cov
    for i, k in enumerate(involved_e):
        j = nb + i
        cov[3 * j:3 * j + 3, 3 * j:3 * j + 3] = ep[k].cov
    gain, bias_cov, weight_epoch = None, np.zeros((3, 3)), 0.0
    if mode == "auto":
        tilt = None if expected_sigmas else bending_tilt(base, ep, meas, stable)
        gain, bias_cov, weight_epoch = normal_gain(lambda x: _normals(*split(x), stable, meas_base, meas, mw)[1:3],  # type: ignore[call-arg]
                                                   x0, cov, expected=expected_sigmas, bending_tilt=tilt)
        if weight_epoch > 0.5:
            flags.append(FLAG_NORMAL_FROM_EPOCH)

    axis = _oriented_along_axis(base, meas_base, stable, up, first_reference)

    def f(x):
        xb, xe = split(x)
        return _vertical_positions(xb, xe, stable, meas_base, meas, mode, w_ref, mw, gain, axis)

    h1, hk, gk, sk, along0 = f(x0)
    u0 = hk - h1
    jac, jac_al = _jacobians(f, x0, len(meas), along0 is not None)
    var = np.einsum("ij,jk,ik->i", jac, cov, jac)
    own = _own_variance(jac, cov, meas, involved_b, involved_e)
    # the deformation bias the combined normal may still carry, through each target's lever p = b - s
    normal_var = np.array([(ep[m].xyz - sk) @ bias_cov @ (ep[m].xyz - sk) for m in meas])
    var_al = np.einsum("ij,jk,ik->i", jac_al, cov, jac_al) if jac_al is not None else None
    out = []
    for m in meas_ids:
        if m in meas:
            i = meas.index(m)
            noise = float(np.sqrt(max(own[i], 0.0)))
            frame = float(np.sqrt(max(var[i] - own[i] + normal_var[i], 0.0)))
            al = (float(along0[i]), float(np.sqrt(max(var_al[i], 0.0)))) if var_al is not None else (np.nan, np.nan)
            out.append(Displacement(m, float(u0[i]), float(np.hypot(noise, frame)), float(hk[i]), float(h1[i]),
                                    (weak,) if weak else (), along_m=al[0], along_sigma_m=al[1],
                                    budget={"noise": noise, "frame": frame}))
        else:
            flag = FLAG_MISSING_AT_BASELINE if m not in base else FLAG_MISSING
            out.append(Displacement(m, float("nan"), float("nan"), float("nan"), float("nan"), (flag,)))
    inputs = tuple(("baseline", k) for k in involved_b) + tuple(("epoch", k) for k in involved_e)
    sens = Sensitivity(tuple(meas), inputs, jac, jac_al if jac_al is not None else np.full_like(jac, np.nan))
    return EpochDisplacements(tuple(out), tuple(stable), checks, gk, sk, mode, tuple(flags), sens)


#: A rotation of the frame motion whose sigma moves some deck target's height by more than this (m) is
#: undetermined: ``reference_geometry_weak`` (a problem) on the epoch and on every row.
WEAK_GEOMETRY_M = 0.005


def _weak_geometry(base: Mapping[str, Observation], stable: Sequence[str], meas_base: Sequence[str],
                   meas: Sequence[str], up: np.ndarray, mw: MotionWeights) -> str | None:
    """The ``reference_geometry_weak`` flag when a rotation of the frame motion is not fixed, else None.

    The motion's rotation covariance (:func:`lidar.reference_motion.rotation_covariance`) along each of its
    axes, times the largest height lever a deck target has about that axis through the reference targets.
    """
    ref = np.array([base[r].xyz for r in stable])
    deck_ids = [m for m in mw.deck_ids if m in base]
    cov = rotation_covariance(ref, mw.ref_var, deck_base=np.array([base[m].xyz for m in deck_ids]) if deck_ids
                              else None, deck_var_across=mw.deck_var, across_base=mw.across)
    vals, vecs = np.linalg.eigh(cov)
    centre = ref.mean(axis=0)
    levers = np.array([base[m].xyz for m in meas_base]) - centre
    worst, axis = 0.0, None
    for k in range(3):
        v = vecs[:, k]
        effect = float(np.sqrt(max(vals[k], 0.0)) * np.max(np.abs(np.cross(v, levers) @ up)))
        if effect > worst:
            worst, axis = effect, v
    if worst <= WEAK_GEOMETRY_M or axis is None:
        return None
    if abs(axis @ up) > 0.7:
        name = "heading about the vertical"
    elif mw.across is not None and abs(axis @ mw.across) > 0.7:
        name = "pitch about the across-span axis"
    else:
        name = "roll about the bridge axis"
    how = "undetermined" if worst > 1.0 else f"known only to {worst * 1e3:.0f} mm on the deck"
    return f"{FLAG_REFERENCE_GEOMETRY_WEAK}: {name} {how} ({len(stable)} reference targets)"


def _jacobians(f: Callable, x0: np.ndarray, n: int, with_along: bool, step: float = 1e-6
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """Central-difference Jacobians of the displacements (and the along-span movements) over the inputs."""
    jac = np.empty((n, x0.size))
    jac_al = np.empty((n, x0.size)) if with_along else None
    for j in range(x0.size):
        xp, xm = x0.copy(), x0.copy()
        xp[j] += step
        xm[j] -= step
        hp1, hpk, _, _, ap = f(xp)
        hm1, hmk, _, _, am = f(xm)
        jac[:, j] = ((hpk - hp1) - (hmk - hm1)) / (2 * step)
        if jac_al is not None:
            jac_al[:, j] = (ap - am) / (2 * step)
    return jac, jac_al


def _own_variance(jac: np.ndarray, cov: np.ndarray, meas: list, involved_b: list, involved_e: list) -> np.ndarray:
    """Each target's variance from its own two centroids (baseline and epoch) alone."""
    nb = len(involved_b)
    out = np.zeros(len(meas))
    for i, m in enumerate(meas):
        cols = []
        if m in involved_b:
            k = involved_b.index(m)
            cols += [3 * k, 3 * k + 1, 3 * k + 2]
        if m in involved_e:
            k = nb + involved_e.index(m)
            cols += [3 * k, 3 * k + 1, 3 * k + 2]
        jj = jac[i, cols]
        out[i] = float(jj @ cov[np.ix_(cols, cols)] @ jj)
    return out


def _oriented_along_axis(base: dict, meas_base: list, stable: list, up: np.ndarray,
                         first_reference: str | None) -> np.ndarray | None:
    """The bridge axis in the baseline frame, horizontal, pointing away from the first pier (None if unknown).

    The deck targets' long horizontal axis, oriented so that ``first_reference`` (default: the first
    stable reference target) lies behind the deck's centre.
    """
    axis = across_axis(np.array([base[m].xyz for m in meas_base]), up)
    if axis is None:
        return None
    along = np.cross(axis, up)
    along /= np.linalg.norm(along)
    ref = first_reference if first_reference in base else (stable[0] if stable else None)
    if ref is None:
        return None
    centre = np.mean([base[m].xyz for m in meas_base], axis=0)
    return along if along @ (base[ref].xyz - centre) < 0 else -along

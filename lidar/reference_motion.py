"""The motion between two epochs' scanner frames, from the reference targets and the deck's sideways stability.

The pier (reference) targets fix the motion between the baseline's and an
epoch's scanner frames, but pier targets sit close together: two targets 1.8 m
apart on each pier of a 40 m span leave the rotation about the bridge axis
weakly determined (a tenth of a millimetre of centroid noise over 1.8 m), and
that rotation tilts the deck normal sideways. The deck targets help: a deck
moves vertically under load and along the span with temperature, but not
across it. Their across-span coordinate is therefore an observation of the
frame motion with a lever of the deck's height above the piers, several metres.

:func:`fit_reference_motion` finds the rigid motion that best maps the
baseline reference targets onto the epoch's (all three coordinates) and the
baseline deck targets onto the epoch's in the across-span direction only, each
residual weighted by its variance.
"""
from __future__ import annotations

import numpy as np

from common.rigid import fit_rigid, rotation_from_rotvec, skew

#: The deck targets must spread at least this far along the span (m) for its axis to be known;
#: below this the deck term is left out.
MIN_ALONG_SPREAD_M = 1.0


def across_axis(deck_xyz: np.ndarray, up: np.ndarray) -> np.ndarray | None:
    """Horizontal unit vector across the span (perpendicular to ``up`` and to the deck targets' long axis).

    None when the deck targets do not spread along a direction (fewer than 2, or all within 1 m).
    """
    deck_xyz = np.asarray(deck_xyz, dtype=np.float64)
    if len(deck_xyz) < 2:
        return None
    c = deck_xyz - deck_xyz.mean(axis=0)
    c -= np.outer(c @ up, up)  # horizontal part
    w, v = np.linalg.eigh(c.T @ c)
    if np.sqrt(w[-1] / len(deck_xyz)) < MIN_ALONG_SPREAD_M / 2:
        return None
    a = np.cross(up, v[:, -1])
    return a / np.linalg.norm(a)


def fit_reference_motion(ref_base: np.ndarray, ref_epoch: np.ndarray, ref_var: np.ndarray, *,
                         deck_base: np.ndarray | None = None, deck_epoch: np.ndarray | None = None,
                         deck_var_across: np.ndarray | None = None, across_base: np.ndarray | None = None,
                         iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Rigid motion (R, t) with ``epoch ~= R @ base + t`` from reference targets and deck sideways stability.

    Parameters
    ----------
    ref_base, ref_epoch : (N, 3) float64 arrays, metres
        The same reference targets in the baseline's and the epoch's scanner frames (N >= 3).
    ref_var : (N,) array, m^2
        Variance of one coordinate of each reference target's difference (both epochs together).
    deck_base, deck_epoch : (M, 3) float64 arrays, optional
        Deck (measurement) targets found in both epochs.
    deck_var_across : (M,) array, m^2, optional
        Variance of each deck target's across-span difference.
    across_base : (3,) array, optional
        Unit across-span axis in the baseline frame (:func:`across_axis`). Without it, or
        without deck targets, the fit uses the reference targets alone.
    iterations : int, keyword-only
        Gauss-Newton steps from the reference-only Kabsch solution (default 3; it converges in 2).

    Returns
    -------
    R : (3, 3) rotation, t : (3,) translation.
    """
    ref_base = np.asarray(ref_base, dtype=np.float64)
    ref_epoch = np.asarray(ref_epoch, dtype=np.float64)
    w_ref = 1.0 / np.maximum(np.asarray(ref_var, dtype=np.float64), 1e-16)
    first = fit_rigid(ref_base, ref_epoch, weights=w_ref)
    r0, t0 = first.rotation, first.translation
    use_deck = across_base is not None and deck_base is not None and len(deck_base) >= 1
    if not use_deck:
        return r0, t0
    deck_base = np.asarray(deck_base, dtype=np.float64)
    deck_epoch = np.asarray(deck_epoch, dtype=np.float64)
    w_deck = 1.0 / np.maximum(np.asarray(deck_var_across, dtype=np.float64), 1e-16)
    # Work about the reference targets' centroid for a well-conditioned system.
    c = (w_ref @ ref_base) / w_ref.sum()
    rot, t = r0, t0 + r0 @ c - c  # t now maps (x - c): epoch ~= rot (x - c) + c + t
    nr, nd = len(ref_base), len(deck_base)
    eye_rows = np.tile(np.eye(3), (nr, 1))  # d(residual)/dt of the reference rows
    for _ in range(iterations):
        a = rot @ across_base
        q = (ref_base - c) @ rot.T
        res_r = (ref_epoch - (q + c + t)).reshape(-1)
        jw_r = -skew(q).reshape(-1, 3)  # d(q)/d(omega) for rot <- (I + [omega]x) rot
        qd = (deck_base - c) @ rot.T
        res_d = (deck_epoch - (qd + c + t)) @ a
        jw_d = np.cross(qd, a)  # a . (-[q]x omega) = (q x a) . omega
        jac = np.vstack([np.hstack([jw_r, eye_rows]), np.hstack([jw_d, np.tile(a, (nd, 1))])])
        rhs = np.concatenate([res_r, res_d])
        sw = np.sqrt(np.concatenate([np.repeat(w_ref, 3), w_deck]))
        step, *_ = np.linalg.lstsq(jac * sw[:, None], rhs * sw, rcond=None)
        rot = rotation_from_rotvec(step[:3]) @ rot
        t = t + step[3:]
    return rot, t + c - rot @ c


def rotation_covariance(ref_base: np.ndarray, ref_var: np.ndarray, *, deck_base: np.ndarray | None = None,
                        deck_var_across: np.ndarray | None = None,
                        across_base: np.ndarray | None = None) -> np.ndarray:
    """(3, 3) covariance (rad^2) of the motion's rotation that :func:`fit_reference_motion` would fit.

    From the fit's normal matrix at the identity (the translation marginalised); infinite along a rotation
    the observations cannot fix (reference targets all on one line, with no deck term to hold the roll
    about it). Same parameters as :func:`fit_reference_motion`.
    """
    ref_base = np.asarray(ref_base, dtype=np.float64)
    w_ref = 1.0 / np.maximum(np.asarray(ref_var, dtype=np.float64), 1e-16)
    c = (w_ref @ ref_base) / w_ref.sum()
    rows = [np.hstack([-skew(ref_base - c).reshape(-1, 3), np.tile(np.eye(3), (len(ref_base), 1))])]
    weights = [np.repeat(w_ref, 3)]
    if across_base is not None and deck_base is not None and len(deck_base) >= 1:
        a = np.asarray(across_base, dtype=np.float64)
        qd = np.asarray(deck_base, dtype=np.float64) - c
        rows.append(np.hstack([np.cross(qd, a), np.tile(a, (len(qd), 1))]))
        weights.append(1.0 / np.maximum(np.asarray(deck_var_across, dtype=np.float64), 1e-16))
    jac, w = np.vstack(rows), np.concatenate(weights)
    normal = jac.T @ (jac * w[:, None])
    vals, vecs = np.linalg.eigh(normal)
    inv = np.where(vals > vals.max() * 1e-13, 1.0 / np.maximum(vals, 1e-300), np.inf)
    full = (vecs * inv) @ vecs.T if np.all(np.isfinite(inv)) else None
    if full is not None:
        return full[:3, :3]
    out = np.zeros((3, 3))  # a null direction: infinite along its rotation part
    for k in np.flatnonzero(~np.isfinite(inv)):
        r = vecs[:3, k]
        if np.linalg.norm(r) > 1e-6:
            r = r / np.linalg.norm(r)
            out += np.outer(r, r) * 1e30
    return out


"""Rigid transforms between matched point sets."""
from __future__ import annotations

import numpy as np

from common.errors import InputError


def fit_rigid(src: np.ndarray, dst: np.ndarray, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation R and translation t with ``dst ~= src @ R.T + t`` (Kabsch, no reflection).

    Parameters
    ----------
    src, dst : (N, 3) float64 arrays of matched points, N >= 3 not collinear.
    weights : (N,) array, optional

    Returns
    -------
    R : (3, 3) rotation, t : (3,) translation.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or src.shape[0] < 3:
        raise InputError("a rigid fit needs two matched (N, 3) point sets with N >= 3")
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    cs = w @ src
    cd = w @ dst
    h = (src - cs).T @ ((dst - cd) * w[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cd - r @ cs


def apply(r: np.ndarray, t: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    return np.asarray(xyz, dtype=np.float64) @ r.T + t


def pairwise_distances(xyz: np.ndarray) -> np.ndarray:
    diff = xyz[:, None, :] - xyz[None, :, :]
    return np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))

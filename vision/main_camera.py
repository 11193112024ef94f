"""The main camera as an affine camera: pixels <-> millimetres on the main target's plane.

With the target far away and the features near the image centre, the main camera's projection
of the target plane is affine: ``[u, v] = Bt @ [x, y] + b`` with ``Bt`` 2x2 (pixels per metre)
and ``b`` the image of WM's origin. It is fitted once, from the first frame, by the
pseudo-inverse of the known feature coordinates (at least three features).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.errors import InputError


@dataclass(frozen=True)
class AffineTargetModel:
    """Affine map from the main target's plane (WM, metres) to main-camera pixels.

    Attributes
    ----------
    Bt : (2, 2) pixels per metre; ``b`` : (2,) pixels of WM's origin in the first frame.
    residual_px : RMS of the fit over the features (0 for exactly three features).
    pattern_m : (N, 2) feature coordinates in WM it was fitted with.
    """

    Bt: np.ndarray
    b: np.ndarray
    residual_px: float
    pattern_m: np.ndarray

    @property
    def mm_per_px(self) -> float:
        """Mean ground sampling of the target plane (millimetres per pixel)."""
        return 1e3 / np.sqrt(abs(np.linalg.det(self.Bt)))

    def to_metres(self, duv_px: np.ndarray) -> np.ndarray:
        """Pixel displacements (..., 2) to target-plane displacements (..., 2) in metres."""
        return np.asarray(duv_px, float) @ np.linalg.inv(self.Bt).T


def fit_affine_target(pattern_m: np.ndarray, uv_px: np.ndarray) -> AffineTargetModel:
    """Fit the affine target model from known feature coordinates and their first-frame pixels.

    Parameters
    ----------
    pattern_m : (N, 2) feature coordinates on the target (WM), metres, N >= 3, not collinear.
    uv_px : (N, 2) their image coordinates (u, v) in the first frame.
    """
    X = np.asarray(pattern_m, float)
    U = np.asarray(uv_px, float)
    if X.ndim != 2 or X.shape[1] != 2 or U.shape != X.shape:
        raise InputError(f"pattern and image points must both be (N, 2); got {X.shape} and {U.shape}")
    if len(X) < 3:
        raise InputError(f"the main target needs at least 3 features for the affine model, got {len(X)}")
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(U))):
        raise InputError("the main target's first frame has missing (NaN) features; choose a frame where all "
                         "features are seen")
    A = np.column_stack([X, np.ones(len(X))])
    if np.linalg.matrix_rank(A) < 3:
        raise InputError("the main target's features are collinear; at least three must span the plane")
    coef = np.linalg.pinv(A) @ U  # (3, 2)
    res = A @ coef - U
    rms = float(np.sqrt((res ** 2).sum(axis=1).mean())) if len(X) > 3 else 0.0
    return AffineTargetModel(Bt=coef[:2].T.copy(), b=coef[2].copy(), residual_px=rms, pattern_m=X.copy())

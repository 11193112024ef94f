"""The sub-camera: intrinsic calibration (Zhang), its pose in every frame and its motion since frame 1."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from common.errors import InputError, ProcessingError
from vision.geometry import invert, rigid


@dataclass(frozen=True)
class Intrinsics:
    """A calibrated camera.

    ``K`` (3x3, pixels), ``distortion`` (OpenCV's k1 k2 p1 p2 k3), the calibration's reprojection RMS in pixels and the number of views it used.
    """

    K: np.ndarray
    distortion: np.ndarray
    rms_px: float
    image_size: tuple[int, int]
    n_views: int


def calibrate_intrinsics(object_points: np.ndarray, image_points: Sequence[np.ndarray], image_size: tuple[int, int],
                         *, distortion: bool = True) -> Intrinsics:
    """Zhang's planar calibration (OpenCV ``calibrateCamera``) from views of a known planar target.

    Parameters
    ----------
    object_points : (M, 3) target coordinates (z = 0), metres.
    image_points : one (M, 2) array per view, pixels; at least 3 views at different tilts.
    image_size : (width, height) in pixels.
    distortion : estimate k1, k2, p1, p2 (k3 fixed at 0); False fits a pure pinhole.
    """
    obj = np.asarray(object_points, np.float32).reshape(-1, 3)
    views = [np.asarray(v, np.float32).reshape(-1, 2) for v in image_points]
    if len(views) < 3:
        raise InputError(f"Zhang calibration needs at least 3 views of the sub-target at different tilts, "
                         f"got {len(views)}")
    if any(len(v) != len(obj) or not np.all(np.isfinite(v)) for v in views):
        raise InputError("every calibration view must hold all the target's points (no NaN)")
    flags = cv2.CALIB_FIX_K3 if distortion else (cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
                                                  | cv2.CALIB_ZERO_TANGENT_DIST)
    rms, K, dist, _, _ = cv2.calibrateCamera([obj] * len(views), views, tuple(int(s) for s in image_size), None,
                                             None, flags=flags,
                                             criteria=(cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 200, 1e-12))
    if not np.isfinite(rms):
        raise ProcessingError("the sub-camera calibration did not converge; use more views at larger tilts")
    return Intrinsics(K=K, distortion=dist.ravel(), rms_px=float(rms), image_size=(int(image_size[0]), int(image_size[1])),
                      n_views=len(views))


def exact_intrinsics(K: np.ndarray, image_size: tuple[int, int]) -> Intrinsics:
    """Known intrinsics (a simulated or factory-calibrated camera) without distortion."""
    return Intrinsics(K=np.asarray(K, float), distortion=np.zeros(5), rms_px=0.0, image_size=(int(image_size[0]), int(image_size[1])),
                      n_views=0)


@dataclass(frozen=True)
class CameraMotion:
    """The sub-camera's motion relative to frame 1, per frame.

    Attributes
    ----------
    B_ws_to_cs : (n, 4, 4) pose of the sub-target in the sub-camera frame (NaN where not seen).
    R : (n, 3, 3) and T : (n, 3) -- ``B_CS(1)->CS(k)``: a point's CS(1) coordinates to CS(k).
    reprojection_px : (n,) RMS reprojection error of each frame's pose.
    valid : (n,) the board was found and the pose solved.
    pose_cov : (n, 6, 6) covariance of each frame's pose (rotation vector rad, translation m)
        from the corners' reprojection scatter; NaN where unknown.
    """

    B_ws_to_cs: np.ndarray
    R: np.ndarray
    T: np.ndarray
    reprojection_px: np.ndarray
    valid: np.ndarray
    pose_cov: np.ndarray


def solve_poses(object_points: np.ndarray, image_points: np.ndarray, intrinsics: Intrinsics, *,
                reference: np.ndarray | None = None, min_sigma_px: float = 0.02) -> CameraMotion:
    """Pose of the sub-target in every frame (PnP) and the motion ``B_CS(1)->CS(k)``.

    Parameters
    ----------
    object_points : (M, 3) sub-target coordinates (WS), metres.
    image_points : (n, M, 2) detected corners per frame; a frame with any NaN counts as not seen.
    intrinsics : the sub-camera's calibration.
    reference : 4x4 pose ``B_WS->CS(1)`` of the initial frame (e.g. the dual calibration's rest
        frame). When None, frame 1 (index 0) is the reference and must be valid.
    min_sigma_px : floor of the corner noise used for the pose covariance.
    """
    obj = np.asarray(object_points, np.float64).reshape(-1, 3)
    pts = np.asarray(image_points, np.float64)
    if pts.ndim != 3 or pts.shape[1:] != (len(obj), 2):
        raise InputError(f"sub-camera points must be (frames, {len(obj)}, 2), got {pts.shape}")
    n = len(pts)
    B = np.full((n, 4, 4), np.nan)
    rep = np.full(n, np.nan)
    cov = np.full((n, 6, 6), np.nan)
    valid = np.zeros(n, bool)
    guess = None
    for k in range(n):
        if not np.all(np.isfinite(pts[k])):
            continue
        if guess is None:
            ok, rvec, tvec = cv2.solvePnP(obj, pts[k], intrinsics.K, intrinsics.distortion,
                                          flags=cv2.SOLVEPNP_IPPE)
        else:
            ok, rvec, tvec = cv2.solvePnP(obj, pts[k], intrinsics.K, intrinsics.distortion, rvec=guess[0].copy(),
                                          tvec=guess[1].copy(), useExtrinsicGuess=True,
                                          flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            continue
        rvec, tvec = cv2.solvePnPRefineLM(obj, pts[k], intrinsics.K, intrinsics.distortion, rvec, tvec,
                                          (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-12))
        proj, jac = cv2.projectPoints(obj, rvec, tvec, intrinsics.K, intrinsics.distortion)
        rep[k] = float(np.sqrt(((proj.reshape(-1, 2) - pts[k]) ** 2).sum(axis=1).mean()))
        J = jac[:, :6]
        sigma = max(rep[k] * np.sqrt(2 * len(obj) / max(2 * len(obj) - 6, 1)) / np.sqrt(2), min_sigma_px)
        cov[k] = sigma ** 2 * np.linalg.pinv(J.T @ J)
        B[k] = rigid(cv2.Rodrigues(rvec)[0], tvec.ravel())
        valid[k] = True
        guess = (rvec, tvec)
    if reference is None:
        if not valid[0]:
            raise ProcessingError("the sub-target is not seen in frame 1; the motion needs a valid first frame")
        reference = B[0]
    motion = np.einsum("kij,jl->kil", B, invert(reference))  # B_WS->CS(k) @ inv(B_WS->CS(1))
    return CameraMotion(B_ws_to_cs=B, R=motion[:, :3, :3], T=motion[:, :3, 3], reprojection_px=rep, valid=valid,
                        pose_cov=cov)


def motion_from_poses(rig_poses: np.ndarray, valid: np.ndarray | None = None) -> CameraMotion:
    """The exact motion of a simulated rig (poses body -> CS(1)), for studies without the sub-camera's errors."""
    P = np.asarray(rig_poses, float)
    motion = invert(P)
    n = len(P)
    return CameraMotion(B_ws_to_cs=np.full((n, 4, 4), np.nan), R=motion[:, :3, :3], T=motion[:, :3, 3],
                        reprojection_px=np.zeros(n), valid=np.ones(n, bool) if valid is None else valid,
                        pose_cov=np.zeros((n, 6, 6)))

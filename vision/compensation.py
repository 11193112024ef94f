"""Camera-motion compensation of the dual-camera system.

The false displacement of main-target feature i in frame k (in main-camera pixels) is

    du_false_i(k) = Bbar_i @ ((R(k) - I) @ X_i + T(k))

where ``R(k), T(k)`` is the sub-camera's motion ``B_CS(1)->CS(k)``, ``X_i`` the feature's position
in CS(1) (metres) and ``Bbar_i`` the 2x3 affine projection from the sub-camera frame to the
main image. The nine unknowns of each feature (six of ``Bbar_i``, three of ``X_i``) are found by
non-linear least squares from H motions of the rig with both targets still. The true
displacement on the target plane is then ``Bt^-1 @ (u_i(k) - u_i(1) - du_false_i(k))``.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from common.errors import InputError, ProcessingError
from common.flags import FLAG_MAIN_TARGET_MISSING, FLAG_SUB_TARGET_MISSING
from common.progress import ProgressCallback, report
from common.rigid import skew
from vision.geometry import rigid_from_rotvec
from vision.main_camera import AffineTargetModel, fit_affine_target
from vision.sub_camera import CameraMotion, Intrinsics, solve_poses

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DualCalibration:
    """The fitted false-displacement model, one per main-target feature.

    Attributes
    ----------
    Bbar : (N, 2, 3) pixels per metre; ``X_cs1`` : (N, 3) metres.
    residual_px : (N,) RMS misfit of each feature's model over the calibration motions.
    n_motions : number of rig motions used (H).
    false_rms_px : RMS size of the false displacement over the calibration motions (the range
        the model was fitted on; beyond it its error grows in proportion).
    """

    Bbar: np.ndarray
    X_cs1: np.ndarray
    residual_px: np.ndarray
    n_motions: int
    false_rms_px: float = float("nan")

    def prediction_sigma_px(self, false_px: np.ndarray) -> np.ndarray:
        """Standard deviation (per image axis) of the predicted false displacement, from the fit's misfit.

        The parameters of a least-squares fit of 9 unknowns to H motions carry about
        ``misfit * sqrt(9 / H)`` of error into a prediction within the calibrated range, growing
        in proportion beyond it. ``false_px`` (..., 2): the predicted false displacement.
        """
        size = np.linalg.norm(np.asarray(false_px, float), axis=-1)
        scale = np.maximum(1.0, size / self.false_rms_px) if np.isfinite(self.false_rms_px) else 1.0
        return float(np.mean(self.residual_px)) * np.sqrt(9.0 / max(self.n_motions, 9)) / np.sqrt(2.0) * scale

    def false_displacement_px(self, R: np.ndarray, T: np.ndarray) -> np.ndarray:
        """Predicted false displacement (n, N, 2) in pixels for motions ``R`` (n, 3, 3), ``T`` (n, 3)."""
        R = np.asarray(R, float).reshape(-1, 3, 3)
        T = np.asarray(T, float).reshape(-1, 3)
        moved = np.einsum("kab,nb->kna", R - np.eye(3), self.X_cs1) + T[:, None, :]  # (n, N, 3)
        return np.einsum("nab,knb->kna", self.Bbar, moved)


def _fit_one_feature(duv: np.ndarray, R: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Nine unknowns of one feature from (H, 2) false displacements and motions (H, 3, 3), (H, 3)."""
    omega = Rotation.from_matrix(R).as_rotvec()
    # Linear start: du = C @ omega + Bbar @ T with C = -Bbar [X]x (small rotations).
    A = np.column_stack([omega, T])
    coef, *_ = np.linalg.lstsq(A, duv, rcond=None)  # (6, 2)
    C, Bbar = coef[:3].T, coef[3:].T
    # C_a = X x Bbar_a = -[Bbar_a]x X for both image rows.
    M = np.vstack([-skew(Bbar[0]), -skew(Bbar[1])])
    X, *_ = np.linalg.lstsq(M, C.ravel(), rcond=None)
    RmI = R - np.eye(3)

    def residual(theta):
        B = theta[:6].reshape(2, 3)
        return ((np.einsum("kab,b->ka", RmI, theta[6:]) + T) @ B.T - duv).ravel()

    sol = least_squares(residual, np.concatenate([Bbar.ravel(), X]), method="lm", x_scale="jac",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000)
    rms = float(np.sqrt((sol.fun ** 2).reshape(-1, 2).sum(axis=1).mean()))
    return sol.x[:6].reshape(2, 3), sol.x[6:], rms


def fit_false_displacement(main_uv: np.ndarray, motion: CameraMotion) -> DualCalibration:
    """Fit the false-displacement model from calibration frames (targets still, rig moved).

    Parameters
    ----------
    main_uv : (H+1, N, 2) main-target features per frame; frame 0 is the rest position.
    motion : the sub-camera motion of the same frames relative to the rest frame.
    """
    uv = np.asarray(main_uv, float)
    if uv.ndim != 3 or uv.shape[2] != 2 or len(uv) != len(motion.R):
        raise InputError(f"calibration needs main-camera points (frames, features, 2) for every frame of the "
                         f"sub-camera motion; got {uv.shape} for {len(motion.R)} frames")
    ok = motion.valid & np.all(np.isfinite(uv), axis=(1, 2))
    if not ok[0]:
        raise ProcessingError("the rest frame of the calibration is incomplete (a target not seen)")
    ok[0] = False
    H = int(ok.sum())
    if H < 6:
        raise ProcessingError(f"the dual-camera calibration needs at least 6 usable rig motions, got {H}; "
                              "move the rig about and along all three axes (the dissertation used 21)")
    R, T = motion.R[ok], motion.T[ok]
    spread_r = np.ptp(Rotation.from_matrix(R).as_rotvec(), axis=0)
    spread_t = np.ptp(T, axis=0)
    if np.any(spread_r < 1e-5) or np.any(spread_t < 1e-5):
        raise ProcessingError("the calibration motions do not excite all six degrees of freedom (rotation "
                              f"spread {np.round(spread_r * 1e3, 3)} mrad, translation spread "
                              f"{np.round(spread_t * 1e3, 3)} mm); move the rig about and along every axis")
    duv = uv[ok] - uv[0]
    fits = [_fit_one_feature(duv[:, i], R, T) for i in range(uv.shape[1])]
    return DualCalibration(Bbar=np.stack([f[0] for f in fits]), X_cs1=np.stack([f[1] for f in fits]),
                           residual_px=np.array([f[2] for f in fits]), n_motions=H,
                           false_rms_px=float(np.sqrt(np.mean(np.sum(duv.mean(axis=1) ** 2, axis=-1)))))


@dataclass(frozen=True)
class DualCameraSetup:
    """Everything the measurement stage needs.

    The affine target model, the sub-camera's intrinsics and rest pose, the rest-frame main-target pixels and the dual calibration.
    """

    target: AffineTargetModel
    intrinsics: Intrinsics
    board_points_m: np.ndarray
    rest_B_ws_to_cs: np.ndarray
    rest_main_uv: np.ndarray
    calibration: DualCalibration


def calibrate_dual_camera(main_uv: np.ndarray, sub_uv: np.ndarray, *, pattern_m: np.ndarray,
                          board_points_m: np.ndarray, intrinsics: Intrinsics) -> DualCameraSetup:
    """The calibration stage from detected features.

    Parameters
    ----------
    main_uv : (H+1, N, 2) main-target features; frame 0 is the rest position.
    sub_uv : (H+1, M, 2) sub-target corners of the same frames.
    pattern_m : (N, 2) main-target feature coordinates in WM (x right, y up), metres.
    board_points_m : (M, 3) sub-target corner coordinates in WS, metres.
    intrinsics : the sub-camera's calibration (:func:`vision.sub_camera.calibrate_intrinsics`).
    """
    uv = np.asarray(main_uv, float)
    target = fit_affine_target(pattern_m, uv[0])
    motion = solve_poses(board_points_m, sub_uv, intrinsics)
    cal = fit_false_displacement(uv, motion)
    log.info("dual calibration: %d motions, misfit %s px", cal.n_motions, np.round(cal.residual_px, 3))
    return DualCameraSetup(target=target, intrinsics=intrinsics, board_points_m=np.asarray(board_points_m, float),
                           rest_B_ws_to_cs=motion.B_ws_to_cs[0], rest_main_uv=uv[0].copy(), calibration=cal)


@dataclass(frozen=True)
class DualCameraResult:
    """Displacement of the main target per frame, in WM (x right, y up), metres.

    Attributes
    ----------
    displacement_m : (n, 2) compensated (true) displacement, mean over the features.
    sigma_m : (n, 2) its standard deviation: feature scatter, the sub-camera pose's uncertainty and
        the calibration's (from its misfit, growing beyond the calibrated range of motion).
    single_camera_m : (n, 2) what the main camera alone gives (false displacement included).
    false_displacement_m : (n, 2) the predicted false displacement that was removed.
    per_feature_m : (n, N, 2) compensated displacement of every feature.
    valid : (n,) both cameras saw their targets.
    flags : one tuple of strings per frame (``main_target_missing``, ``sub_target_missing``).
    provenance : calibration figures (motions used, misfit, mm per pixel, intrinsics RMS).
    """

    displacement_m: np.ndarray
    sigma_m: np.ndarray
    single_camera_m: np.ndarray
    false_displacement_m: np.ndarray
    per_feature_m: np.ndarray
    valid: np.ndarray
    flags: tuple
    provenance: dict = field(default_factory=dict)

    @property
    def vertical_mm(self) -> np.ndarray:
        return self.displacement_m[:, 1] * 1e3


def _pose_params(B: np.ndarray) -> np.ndarray:
    return np.concatenate([Rotation.from_matrix(B[:3, :3]).as_rotvec(), B[:3, 3]])


def measure_dual_camera(setup: DualCameraSetup, main_uv: np.ndarray, sub_uv: np.ndarray | None = None, *,
                        motion: CameraMotion | None = None,
                        progress: ProgressCallback | None = None) -> DualCameraResult:
    """The measurement stage: compensated displacement of the main target in every frame.

    Parameters
    ----------
    setup : from :func:`calibrate_dual_camera`.
    main_uv : (n, N, 2) main-target features per frame (NaN where not found).
    sub_uv : (n, M, 2) sub-target corners per frame; or give ``motion`` directly.
    """
    uv = np.asarray(main_uv, float)
    N = len(setup.target.pattern_m)
    if uv.ndim != 3 or uv.shape[1:] != (N, 2):
        raise InputError(f"main-camera points must be (frames, {N}, 2), got {uv.shape}")
    if motion is None:
        if sub_uv is None:
            raise InputError("give the sub-camera's corners (sub_uv) or its motion")
        motion = solve_poses(setup.board_points_m, sub_uv, setup.intrinsics, reference=setup.rest_B_ws_to_cs)
    n = len(uv)
    cal = setup.calibration
    Binv = np.linalg.inv(setup.target.Bt)
    measured_px = uv - setup.rest_main_uv
    false_px = np.full((n, N, 2), np.nan)
    okm = motion.valid
    false_px[okm] = cal.false_displacement_px(motion.R[okm], motion.T[okm])
    per_feature = (measured_px - false_px) @ Binv.T
    single = (measured_px @ Binv.T).mean(axis=1)  # NaN where a feature is missing
    found = np.all(np.isfinite(uv), axis=(1, 2))
    valid = found & okm
    disp = np.where(valid[:, None], per_feature.mean(axis=1), np.nan)
    scatter = np.where(valid[:, None], per_feature.std(axis=1, ddof=1) / np.sqrt(N), np.nan) if N > 1 else 0.0
    pose_sigma = np.zeros((n, 2))
    inv_ref = np.linalg.inv(setup.rest_B_ws_to_cs)
    for k in np.nonzero(valid & np.all(np.isfinite(motion.pose_cov), axis=(1, 2))
                        & np.isfinite(motion.B_ws_to_cs[:, 0, 0]))[0]:
        p0 = _pose_params(motion.B_ws_to_cs[k])
        J = np.zeros((2, 6))
        for j in range(6):
            h = 1e-6
            dp = np.zeros(6)
            dp[j] = h
            M = rigid_from_rotvec(p0[:3] + dp[:3], p0[3:] + dp[3:]) @ inv_ref
            f1 = cal.false_displacement_px(M[None, :3, :3], M[None, :3, 3])[0].mean(axis=0)
            M = rigid_from_rotvec(p0[:3] - dp[:3], p0[3:] - dp[3:]) @ inv_ref
            f0 = cal.false_displacement_px(M[None, :3, :3], M[None, :3, 3])[0].mean(axis=0)
            J[:, j] = Binv @ (f1 - f0) / (2 * h)
        pose_sigma[k] = np.sqrt(np.clip(np.diag(J @ motion.pose_cov[k] @ J.T), 0, None))
        if progress is not None and k % 50 == 0:
            report(progress, k / n, f"frame {k + 1} of {n}")
    mean_false = false_px.mean(axis=1)
    cal_sigma = np.where(valid[:, None], (cal.prediction_sigma_px(mean_false) * setup.target.mm_per_px / 1e3)[..., None],
                         np.nan)
    sigma = np.sqrt(scatter ** 2 + pose_sigma ** 2 + cal_sigma ** 2)
    flags = tuple(tuple(f for f, bad in ((FLAG_MAIN_TARGET_MISSING, not found[k]), (FLAG_SUB_TARGET_MISSING, not okm[k]))
                        if bad) for k in range(n))
    prov = {"calibration_motions": cal.n_motions, "calibration_misfit_px": cal.residual_px.tolist(),
            "target_mm_per_px": setup.target.mm_per_px, "target_fit_px": setup.target.residual_px,
            "intrinsics_rms_px": setup.intrinsics.rms_px, "features": N}
    report(progress, 1.0, "done")
    return DualCameraResult(displacement_m=disp, sigma_m=sigma, single_camera_m=single,
                            false_displacement_m=(false_px @ Binv.T).mean(axis=1), per_feature_m=per_feature,
                            valid=valid, flags=flags, provenance=prov)

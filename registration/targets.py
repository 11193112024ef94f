"""Registration of two epochs on matched targets (tie points), with a residual table and moved-target checks."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from common.rigid import fit_rigid
from registration.errors import InputError, RegistrationError
from registration.transform import Transform

MODES = ("rigid", "similarity", "yaw")
MIN_POINTS = {"rigid": 3, "similarity": 3, "yaw": 2}


@dataclass(frozen=True)
class TieResidual:
    """How one tie point fits: residual after the fit, and after a fit without it (leave-one-out)."""

    id: str
    residual_m: tuple[float, ...]
    residual_norm_m: float
    loo_residual_m: float
    used: bool
    fits: bool


@dataclass(frozen=True, eq=False)
class TargetRegistration:
    """Result of :func:`register_targets`.

    Attributes
    ----------
    transform : Transform
        From the ``from`` epoch's frame to the ``to`` frame.
    residuals : tuple of TieResidual
        One per tie point (in the order given).
    rms_m : float
        RMS residual norm of the tie points used, metres.
    mode : str
    warnings : tuple of str
        e.g. a tie point that does not fit (a moved target), left out of the fit.
    """

    transform: Transform
    residuals: tuple[TieResidual, ...]
    rms_m: float
    mode: str
    warnings: tuple[str, ...]

    @property
    def used_ids(self) -> tuple[str, ...]:
        return tuple(r.id for r in self.residuals if r.used)

    def table(self) -> list[dict]:
        return [{"target": r.id, "dx_mm": r.residual_m[0] * 1e3, "dy_mm": r.residual_m[1] * 1e3,
                 "dz_mm": r.residual_m[2] * 1e3, "residual_mm": r.residual_norm_m * 1e3,
                 "leave_one_out_mm": r.loo_residual_m * 1e3, "used": r.used, "fits": r.fits} for r in self.residuals]


def _fit(src: np.ndarray, dst: np.ndarray, mode: str, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, t, s) with dst ~= s R src + t."""
    if mode == "yaw":
        ww = w / w.sum()
        cs, cd = ww @ src, ww @ dst
        a, b = src[:, :2] - cs[:2], dst[:, :2] - cd[:2]
        num = np.sum(ww * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))
        den = np.sum(ww * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
        yaw = np.arctan2(num, den)
        c, s = np.cos(yaw), np.sin(yaw)
        r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return r, cd - r @ cs, 1.0
    fit = fit_rigid(src, dst, w)
    r, t = fit.rotation, fit.translation
    if mode == "rigid":
        return r, t, 1.0
    ww = w / w.sum()
    cs, cd = ww @ src, ww @ dst
    a, b = src - cs, dst - cd
    s = float(np.sum(ww[:, None] * (b * (a @ r.T))) / np.sum(ww[:, None] * a * a))
    return r, cd - s * (r @ cs), s


def register_targets(xyz_from: np.ndarray, xyz_to: np.ndarray, ids: Sequence[str], *, mode: str = "rigid",
                     sigma_m: np.ndarray | None = None, tolerance_m: float = 0.002,
                     source_frame: str = "", target_frame: str = "") -> TargetRegistration:
    """Transform taking ``xyz_from`` onto ``xyz_to`` from matched tie points.

    Parameters
    ----------
    xyz_from, xyz_to : (N, 3) float64 arrays, metres
        The same targets measured in the two frames (e.g. reference-target centroids of two epochs).
    ids : sequence of N str
    mode : {"rigid", "similarity", "yaw"}, keyword-only
        ``rigid`` (6 parameters, default, needs 3 targets), ``similarity`` (plus a scale, 3 targets) or
        ``yaw`` (rotation about z and a translation, for two levelled set-ups, 2 targets).
    sigma_m : (N,) array, optional
        Standard deviation of each tie point's position (both epochs combined); weights the fit.
        Default: equal weights and 0.5 mm.
    tolerance_m : float, keyword-only
        A tie point whose leave-one-out residual exceeds this (default 2 mm) does not fit; with at
        least one target to spare it is left out and a warning is given.

    Returns
    -------
    TargetRegistration
    """
    src = np.asarray(xyz_from, dtype=np.float64)
    dst = np.asarray(xyz_to, dtype=np.float64)
    ids = [str(i) for i in ids]
    if mode not in MODES:
        raise InputError(f"registration mode {mode!r} unknown; use one of {', '.join(MODES)}")
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or len(ids) != len(src):
        raise InputError("target registration needs two (N, 3) arrays of the same targets and N ids")
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    need = MIN_POINTS[mode]
    if ok.sum() < need:
        raise RegistrationError(f"{mode} registration needs at least {need} targets seen in both epochs, got "
                                f"{int(ok.sum())} ({', '.join(i for i, k in zip(ids, ok, strict=True) if k) or 'none'}); "
                                + ("try --mode yaw for two targets on levelled set-ups" if mode != "yaw" else
                                   "check that the reference targets were found"))
    sig = np.full(len(src), 5e-4) if sigma_m is None else np.asarray(sigma_m, dtype=np.float64)
    if sig.shape != (len(src),) or np.any(~np.isfinite(sig[ok])) or np.any(sig[ok] <= 0):
        raise InputError("sigma_m must hold one positive value per tie point")
    w = 1.0 / sig ** 2
    used = ok.copy()
    warnings = []
    loo = np.full(len(src), np.nan)
    while True:
        idx = np.flatnonzero(used)
        loo[idx] = np.nan  # left-out targets keep the residual that had them left out
        if len(idx) > need:
            for k in idx:
                rest = idx[idx != k]
                r, t, s = _fit(src[rest], dst[rest], mode, w[rest])
                loo[k] = np.linalg.norm(s * r @ src[k] + t - dst[k])
        bad = [k for k in idx if np.isfinite(loo[k]) and loo[k] > tolerance_m]
        if not bad or len(idx) - 1 < need:
            break
        worst = max(bad, key=lambda k: loo[k])  # the rest fit best without the culprit
        used[worst] = False
        warnings.append(f"target {ids[worst]} does not fit (leave-one-out residual {loo[worst] * 1e3:.1f} mm): "
                        "it may have moved; left out of the registration")
    idx = np.flatnonzero(used)
    r, t, s = _fit(src[idx], dst[idx], mode, w[idx])
    res = dst - (s * src @ r.T + t)
    rms = float(np.sqrt(np.mean(np.sum(res[idx] ** 2, axis=1))))
    for k in np.flatnonzero(ok & used):
        if np.isfinite(loo[k]) and loo[k] > tolerance_m:
            warnings.append(f"target {ids[k]} fits poorly (leave-one-out residual {loo[k] * 1e3:.1f} mm) but too few "
                            "targets remain to leave it out")
    if len(idx) == need and mode != "similarity":
        warnings.append(f"only {need} targets: no redundancy, a moved target cannot be detected")
    for k in np.flatnonzero(~ok):
        warnings.append(f"target {ids[k]} missing in one epoch")
    # Precision: translation from the weighted mean; rotation from the lever arms of the tie points.
    ww = w[idx] / w[idx].sum()
    sig_eff = float(np.sqrt(1.0 / w[idx].sum()))
    arm = float(np.sqrt(np.sum(ww * np.sum((src[idx] - ww @ src[idx]) ** 2, axis=1))))
    sig_rot = float(np.degrees(sig_eff / max(arm, 1e-9)))
    rows = tuple(TieResidual(ids[k], tuple(float(v) for v in res[k]) if ok[k] else (np.nan,) * 3,
                             float(np.linalg.norm(res[k])) if ok[k] else float("nan"), float(loo[k]), bool(used[k]),
                             bool(ok[k] and (not np.isfinite(loo[k]) or loo[k] <= tolerance_m) and used[k]))
                 for k in range(len(src)))
    tf = Transform(r, t, s, source_frame, target_frame, sig_eff, sig_rot, f"targets:{mode}")
    return TargetRegistration(tf, rows, rms, mode, tuple(warnings))

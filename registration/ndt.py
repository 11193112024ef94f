"""NDT refinement of a registration through PCL's own program ``pcl_ndt3d`` (Debian ``pcl-tools``).

Surveyors who know PCL can compare its Normal Distributions Transform with
our Open3D ICP on the same stable parts. The clouds are written as binary PCD
in coordinates reduced by an offset (PCL works in float32), the source already
moved by the initial transform, so NDT only estimates the small correction.
``pcl_ndt3d`` prints the correction it found; nothing else of its output is
used. The result has the same type as :func:`registration.icp.refine_icp`'s.
"""
from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from common.arrays import thin_to_voxels
from common.pcd import binary_pcd_header
from common.progress import ProgressCallback, report
from registration.errors import InputError, RegistrationError
from registration.icp import IcpResult, check_clouds
from registration.transform import Transform

PROGRAM = "pcl_ndt3d"
_ROW = re.compile(r"^\s*(-?[0-9.eE+-]+)\s+(-?[0-9.eE+-]+)\s+(-?[0-9.eE+-]+)\s+(-?[0-9.eE+-]+)\s*$")


def ndt_available() -> bool:
    """Whether PCL's ``pcl_ndt3d`` program is on the PATH."""
    return shutil.which(PROGRAM) is not None


def _write_pcd(path: Path, xyz: np.ndarray) -> None:
    rec = np.ascontiguousarray(xyz, dtype="<f4").view([("x", "<f4"), ("y", "<f4"), ("z", "<f4")]).reshape(-1)
    path.write_bytes(binary_pcd_header(rec.dtype, len(rec)) + rec.tobytes())


def parse_transform(text: str) -> np.ndarray:
    """The last 4x4 matrix ``pcl_ndt3d`` printed (four rows of four numbers)."""
    rows = [ln for ln in text.splitlines() if _ROW.match(ln)]
    if len(rows) < 4:
        raise RegistrationError(f"{PROGRAM} printed no transform; its output ended with: "
                                f"{(text.strip().splitlines() or ['(nothing)'])[-1][:120]}")
    mat = np.array([[float(v) for v in m.groups()] for r in rows[-4:] if (m := _ROW.match(r)) is not None])
    if not np.isfinite(mat).all() or not np.allclose(mat[3], (0, 0, 0, 1)):
        raise RegistrationError(f"{PROGRAM} printed an invalid transform")
    return mat


def refine_ndt(source_xyz: np.ndarray, target_xyz: np.ndarray, initial: Transform, *, resolution_m: float = 1.0,
               step_m: float = 0.05, max_iterations: int = 50, epsilon: float = 1e-6, voxel_m: float = 0.04,
               offset: np.ndarray | None = None, timeout_s: float = 600.0,
               progress: ProgressCallback | None = None) -> IcpResult:
    """Refine ``initial`` (source -> target) with PCL's NDT on the stable parts.

    Parameters
    ----------
    source_xyz, target_xyz : (N, 3), (M, 3) float64 arrays, metres
        Points of the stable parts in each epoch's frame.
    initial : Transform
        Starting transform, e.g. from the reference targets.
    resolution_m : float, keyword-only
        NDT grid cell (default 1 m: cells must hold enough points for a normal distribution).
    step_m : float, keyword-only
        Largest Newton step (default 5 cm).
    max_iterations : int, keyword-only
        Default 50.
    epsilon : float, keyword-only
        Termination threshold on the transform change (default 1e-6).
    voxel_m : float, keyword-only
        Both clouds are thinned to one point per voxel of this size first (default 4 cm).
    offset : (3,) array, optional
        Subtracted before writing float32 PCD (default: the target's mean).

    Returns
    -------
    IcpResult
        ``fitness`` is the share of thinned source points within half an NDT
        cell of a target point after the fit, ``rms_m`` their RMS
        nearest-neighbour distance (it includes the sampling); PCL does not
        report its iteration count, so ``iterations`` is empty.

    Raises
    ------
    RegistrationError
        PCL is not installed, failed, or found no fit.
    """
    if not ndt_available():
        raise RegistrationError(f"PCL's {PROGRAM} is not installed: install Debian's pcl-tools "
                                "(./run setup does so as root) or use --registration icp")
    src, tgt = check_clouds(source_xyz, target_xyz, "NDT")
    if not (resolution_m > 0 and step_m > 0 and voxel_m > 0 and max_iterations > 0):
        raise InputError("NDT resolution, step, voxel and iterations must be positive")
    off = tgt.mean(axis=0) if offset is None else np.asarray(offset, dtype=np.float64)
    shift = Transform(np.eye(3), -off)
    s = thin_to_voxels(initial.then(shift).apply(src), voxel_m)
    t = thin_to_voxels(tgt - off, voxel_m)
    report(progress, 0.1, f"NDT ({len(s):,} and {len(t):,} points)")
    with tempfile.TemporaryDirectory(prefix="bridgesurvey-ndt-") as tmp_name:
        tmp = Path(tmp_name)
        (tmp / "in").mkdir()
        (tmp / "out").mkdir()
        _write_pcd(tmp / "in" / "target.pcd", t)
        _write_pcd(tmp / "in" / "source.pcd", s)
        cmd = [PROGRAM, str(tmp / "in" / "target.pcd"), str(tmp / "in" / "source.pcd"), "-r", f"{resolution_m}",
               "-s", f"{step_m}", "-i", f"{max_iterations}", "-t", f"{epsilon}"]
        t0 = time.perf_counter()
        try:  # pcl_ndt3d saves its results into the working folder: give it one of its own
            run = subprocess.run(cmd, cwd=tmp / "out", capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired as exc:
            raise RegistrationError(f"{PROGRAM} did not finish within {timeout_s:.0f} s") from exc
        seconds = time.perf_counter() - t0
    if run.returncode != 0:
        raise RegistrationError(f"{PROGRAM} failed (exit {run.returncode}): "
                                f"{(run.stderr.strip().splitlines() or ['no message'])[-1][:120]}")
    corr_reduced = Transform.from_matrix(parse_transform(run.stdout))
    moved = corr_reduced.apply(s)
    d, _ = cKDTree(t).query(moved, distance_upper_bound=resolution_m / 2)
    close = np.isfinite(d)
    fitness = float(close.mean())
    if fitness < 0.2:
        raise RegistrationError(f"NDT matched only {fitness:.0%} of the stable points; the initial registration "
                                "is too far off or the stable areas differ")
    correction = shift.then(corr_reduced).then(shift.inverse())
    result = initial.then(correction)
    result = Transform(result.rotation, result.translation, result.scale, initial.source_frame, initial.target_frame,
                       initial.sigma_translation_m, initial.sigma_rotation_deg, f"{initial.method}+ndt",
                       initial.notes)
    report(progress, 1.0, f"NDT done in {seconds:.1f} s")
    return IcpResult(result, Transform(correction.rotation, correction.translation, 1.0, initial.target_frame,
                                       initial.target_frame, method="ndt"),
                     fitness, float(np.sqrt(np.mean(d[close] ** 2))), (), (float(resolution_m),), len(s), len(t), off)

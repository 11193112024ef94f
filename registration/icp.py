"""ICP refinement of a registration on stable parts of the scene (Open3D point-to-plane, robust kernel)."""
from __future__ import annotations

import contextlib
import io
import re
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from common.progress import ProgressCallback, report
from common.validation import require_points
from registration.errors import InputError, RegistrationError
from registration.transform import Transform

_ITER = re.compile(r"ICP Iteration #(\d+): Fitness ([0-9.]+), RMSE ([0-9.eE+-]+)")


@dataclass(frozen=True, eq=False)
class IcpResult:
    """Result of :func:`refine_icp`.

    Attributes
    ----------
    transform : Transform
        The refined transform (source frame -> target frame).
    correction : Transform
        What ICP changed relative to the initial transform (in the target frame).
    fitness : float
        Share of the source points (finest level) with a correspondence.
    rms_m : float
        Open3D's inlier RMSE at the finest level: the RMS *point-to-point* distance between corresponding
        downsampled points, metres (of the order of the voxel size, not a registration error).
    plane_rms_m : float
        RMS point-to-plane distance of the same correspondences after the fit, metres (the stable parts'
        surface noise plus what the fit leaves).
    iterations : tuple of int
        Iterations run at each level (coarse to fine).
    voxels_m : tuple of float
        Voxel size of each level.
    n_source, n_target : int
        Points used at the finest level.
    offset : (3,) array
        Coordinates were reduced by this offset before solving (numerical safety).
    """

    transform: Transform
    correction: Transform
    fitness: float
    rms_m: float
    iterations: tuple[int, ...]
    voxels_m: tuple[float, ...]
    n_source: int
    n_target: int
    offset: np.ndarray
    plane_rms_m: float = float("nan")


@contextlib.contextmanager
def _capture_stdout():
    """Collect Open3D's debug log of each ICP iteration (its Python module prints through sys.stdout)."""
    buf = io.StringIO()
    box = {}
    try:
        with contextlib.redirect_stdout(buf):
            yield box
    finally:
        box["text"] = buf.getvalue()


def check_clouds(source_xyz: ArrayLike, target_xyz: ArrayLike, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Source and target as float64 (N, 3) arrays of at least 100 finite points, or InputError."""
    out = []
    for name, a in (("source", source_xyz), ("target", target_xyz)):
        out.append(require_points(a, f"{what} {name}", min_points=100))
    return out[0], out[1]


def _cloud(xyz: np.ndarray):
    import open3d as o3d

    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))


def refine_icp(source_xyz: np.ndarray, target_xyz: np.ndarray, initial: Transform, *,
               voxels_m: Sequence[float] = (0.20, 0.08, 0.04), max_iterations: int = 30,
               kernel_sigma_m: Optional[float] = None, offset: Optional[np.ndarray] = None,
               progress: Optional[ProgressCallback] = None) -> IcpResult:
    """Refine ``initial`` (source -> target) by point-to-plane ICP, coarse to fine.

    Parameters
    ----------
    source_xyz, target_xyz : (N, 3), (M, 3) float64 arrays, metres
        Points of the stable parts (piers, ground near them) in each epoch's frame.
    initial : Transform
        Starting transform, e.g. from :func:`registration.targets.register_targets`.
    voxels_m : sequence of float, keyword-only
        Voxel sizes of the levels, coarse to fine (default 20, 8, 4 cm). The correspondence
        distance at each level is 2.5 voxels; normals use a radius of 3 voxels.
    max_iterations : int, keyword-only
        Per level (default 30).
    kernel_sigma_m : float, optional
        Tukey kernel width; default one voxel at each level.
    offset : (3,) array, optional
        Subtracted from all coordinates before solving (default: the target's mean), so large
        project coordinates lose no precision in Open3D's float arithmetic.

    Returns
    -------
    IcpResult
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    src, tgt = check_clouds(source_xyz, target_xyz, "ICP")
    if not voxels_m or any(not (v > 0) for v in voxels_m):
        raise InputError("ICP voxel sizes must be positive")
    off = tgt.mean(axis=0) if offset is None else np.asarray(offset, dtype=np.float64)
    shift = Transform(np.eye(3), -off)
    # Work in reduced coordinates: source is moved by the initial transform and the offset.
    src_cloud = _cloud(initial.then(shift).apply(src))
    tgt_cloud = _cloud(tgt - off)
    current = np.eye(4)
    iterations, last = [], None
    verbosity = o3d.utility.get_verbosity_level()
    for k, v in enumerate(voxels_m):
        report(progress, k / len(voxels_m), f"ICP level {k + 1}/{len(voxels_m)} ({v * 100:.0f} cm)")
        s = src_cloud.voxel_down_sample(v)
        t = tgt_cloud.voxel_down_sample(v)
        t.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * v, max_nn=30))
        loss = reg.TukeyLoss(k=kernel_sigma_m or v)
        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Debug)
        try:
            with _capture_stdout() as out:
                last = reg.registration_icp(s, t, 2.5 * v, current, reg.TransformationEstimationPointToPlane(loss),
                                            reg.ICPConvergenceCriteria(max_iteration=max_iterations))
        finally:
            o3d.utility.set_verbosity_level(verbosity)
        iterations.append(len(_ITER.findall(out["text"])))
        current = np.asarray(last.transformation)
        n_src, n_tgt = len(s.points), len(t.points)
        finest = (s, t, 2.5 * v)
    if last is None or last.fitness < 0.2:
        raise RegistrationError(f"ICP found correspondences for only {0 if last is None else last.fitness:.0%} of the "
                                "stable points; the initial registration is too far off or the stable areas differ")
    plane_rms = _plane_rms(*finest, current)
    corr_reduced = Transform.from_matrix(current)
    # correction in the target frame: x -> off + C (x - off)
    correction = shift.then(corr_reduced).then(shift.inverse())
    result = initial.then(correction)
    result = Transform(result.rotation, result.translation, result.scale, initial.source_frame, initial.target_frame,
                       initial.sigma_translation_m, initial.sigma_rotation_deg, f"{initial.method}+icp", initial.notes)
    report(progress, 1.0, "ICP done")
    return IcpResult(result, Transform(correction.rotation, correction.translation, 1.0, initial.target_frame,
                                       initial.target_frame, method="icp"),
                     float(last.fitness), float(last.inlier_rmse), tuple(iterations), tuple(float(v) for v in voxels_m),
                     n_src, n_tgt, off, plane_rms)


def _plane_rms(source, target, max_distance_m: float, transform: np.ndarray) -> float:
    """RMS point-to-plane distance from the moved source points to their nearest target point's plane."""
    from scipy.spatial import cKDTree

    src = np.asarray(source.points) @ transform[:3, :3].T + transform[:3, 3]
    tgt = np.asarray(target.points)
    normals = np.asarray(target.normals)
    d, k = cKDTree(tgt, balanced_tree=False, compact_nodes=False).query(src, distance_upper_bound=max_distance_m,
                                                                           workers=-1)
    ok = np.isfinite(d)
    if not ok.any():
        return float("nan")
    res = np.einsum("ij,ij->i", src[ok] - tgt[k[ok]], normals[k[ok]])
    return float(np.sqrt(np.mean(res ** 2)))


def stable_mask(xyz: np.ndarray, anchors_xyz: np.ndarray, *, radius_m: float = 4.0,
                exclude_above_m: Optional[float] = None, up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Points near the anchors (reference targets on the piers) and, optionally, below a height.

    Parameters
    ----------
    xyz : (N, 3) array
    anchors_xyz : (K, 3) array
        Reference-target positions in the same frame.
    radius_m : float, keyword-only
        Horizontal distance from the nearest anchor (default 4 m: the pier and the ground around it).
    exclude_above_m : float, optional
        Drop points whose height along ``up`` is above this (e.g. just below the deck, which moves).

    Returns
    -------
    (N,) bool array
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    up_v = np.asarray(up, dtype=np.float64)
    up_v = up_v / np.linalg.norm(up_v)
    anchors = np.asarray(anchors_xyz, dtype=np.float64).reshape(-1, 3)
    if len(anchors) == 0:
        raise InputError("stable areas need at least one anchor (a reference target)")
    # two horizontal axes: distances in that plane, anchor by anchor (a handful), no temporaries of (N, 3)
    e1 = np.cross(up_v, [1.0, 0.0, 0.0] if abs(up_v[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up_v, e1)
    u, v = xyz @ e1, xyz @ e2
    mask = np.zeros(len(xyz), bool)
    r2 = radius_m * radius_m
    for a in anchors:
        du, dv = u - float(a @ e1), v - float(a @ e2)
        du *= du
        dv *= dv
        du += dv
        mask |= du <= r2
    if exclude_above_m is not None:
        mask &= (xyz @ up_v) < exclude_above_m
    return mask

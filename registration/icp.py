"""ICP refinement of a registration on stable parts of the scene (point-to-plane, Tukey kernel).

Our own few dozen lines on scipy's KD-tree rather than Open3D's: the same algorithm, and importing Open3D
(its plotting stack with it) cost every comparison a second.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from common.arrays import unique_sorted
from common.progress import ProgressCallback, report
from common.rigid import rotation_from_rotvec
from common.validation import require_points
from registration.errors import InputError, RegistrationError
from registration.transform import Transform

if TYPE_CHECKING:
    from scipy.spatial import cKDTree


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
        Share of the source points (finest level; at most :data:`FIT_POINTS` of them, evenly spread) with a
        correspondence.
    rms_m : float
        The inlier RMSE at the finest level: the RMS *point-to-point* distance between corresponding
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


def check_clouds(source_xyz: ArrayLike, target_xyz: ArrayLike, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Source and target as float64 (N, 3) arrays of at least 100 finite points, or InputError."""
    out = []
    for name, a in (("source", source_xyz), ("target", target_xyz)):
        out.append(require_points(a, f"{what} {name}", min_points=100))
    return out[0], out[1]


def voxel_centroids(xyz: np.ndarray, voxel_m: float) -> np.ndarray:
    """The mean of the points in each occupied cube of ``voxel_m`` (the downsampling ICP works on).

    Parameters
    ----------
    xyz : (N, 3) float64 array, metres
    voxel_m : float
        Edge of the cubes, metres.

    Returns
    -------
    (M, 3) float64 array
        One point a cube, the cubes in Z-order (Morton order of their integer coordinates): neighbours in
        space lie near each other in memory, which makes the neighbour searches and gathers on them 2-3x
        faster. The same whatever the points' order.
    """
    cell = np.floor(xyz / voxel_m).astype(np.int64)
    cell -= cell.min(axis=0)
    dims = cell.max(axis=0) + 1
    key = _morton(cell) if dims.max() <= 1 << 21 else (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    _, inverse, count = np.unique(key, return_inverse=True, return_counts=True)
    sums = np.column_stack([np.bincount(inverse, weights=xyz[:, k], minlength=count.size) for k in range(3)])
    return sums / count[:, None]


def _morton(cell: np.ndarray) -> np.ndarray:
    """Z-order code of (N, 3) non-negative int64 cell coordinates below 2**21: their bits interleaved."""
    code = np.zeros(len(cell), np.int64)
    for axis in range(3):
        v = cell[:, axis].astype(np.int64)
        v = (v | (v << 32)) & 0x1F00000000FFFF
        v = (v | (v << 16)) & 0x1F0000FF0000FF
        v = (v | (v << 8)) & 0x100F00F00F00F00F
        v = (v | (v << 4)) & 0x10C30C30C30C30C3
        v = (v | (v << 2)) & 0x1249249249249249
        code |= v << axis
    return code


def surface_normals(xyz: np.ndarray, tree: cKDTree, *, radius_m: float, max_nn: int = 30,
                    min_nn: int = 6, which: np.ndarray | None = None) -> np.ndarray:
    """Unit normals of the local planes: the least principal axis of each point's neighbours.

    Parameters
    ----------
    xyz : (N, 3) float64 array, metres
        At least ``min_nn`` points.
    tree : scipy.spatial.cKDTree
        Built on ``xyz``.
    radius_m : float, keyword-only
        Neighbours within this distance count, up to the ``max_nn`` nearest (default 30) ...
    min_nn : int, keyword-only
        ... and where fewer lie that close (a sparse surface), the ``min_nn`` nearest wherever they are
        (default 6): a plane through a few neighbours rather than no normal or a guessed one.
    which : (K,) int array, optional, keyword-only
        Only these points' normals (default all).

    Returns
    -------
    (N, 3) or (K, 3) float64 array
        Unit normals, each of either orientation.
    """
    which = np.arange(len(xyz)) if which is None else np.asarray(which, dtype=np.intp)
    columns = [np.ascontiguousarray(xyz[:, k]) for k in range(3)]  # gathers from a column run 10x faster
    out = np.empty((len(which), 3))
    for lo in range(0, len(which), NORMALS_BLOCK):  # in blocks: the (N, 30) neighbour tables of a large cloud
        hi = min(lo + NORMALS_BLOCK, len(which))     # would take gigabytes of fresh memory
        out[lo:hi] = _block_normals(xyz, columns, which[lo:hi], tree, radius_m, max_nn, min_nn)
    return out


#: Points whose normals are computed at once (bounds the neighbour tables to about 16 MB each).
NORMALS_BLOCK = 65_536


def _block_normals(xyz: np.ndarray, columns: list[np.ndarray], which: np.ndarray, tree: cKDTree, radius_m: float,
                   max_nn: int, min_nn: int) -> np.ndarray:
    """Normals of the points ``xyz[which]`` (see :func:`surface_normals`); ``columns`` are xyz's, contiguous."""
    dist, idx = tree.query(xyz[which], k=min(max_nn, len(xyz)), distance_upper_bound=radius_m, workers=-1)
    inside = np.isfinite(dist)
    sparse = np.flatnonzero(inside.sum(axis=1) < min_nn)
    if sparse.size:
        _, near_sparse = tree.query(xyz[which[sparse]], k=min_nn, workers=-1)
        idx[sparse, :min_nn], inside[sparse, :min_nn], inside[sparse, min_nn:] = near_sparse, True, False
    # a missing neighbour is the point itself: zero offset, so it adds nothing to the sums below. Neighbours
    # run along the first axis and points along the second, so numpy's inner loops run over the points.
    near = np.ascontiguousarray(np.where(inside, idx, which[:, None]).T)  # (k, n)
    count = inside.sum(axis=1).astype(np.float64)
    offsets = []
    for column in columns:
        o = column[near]
        o -= column[which]  # (k, n), metres
        offsets.append(o)
    mean = [o.sum(axis=0) / count for o in offsets]
    cov = np.empty((len(which), 3, 3))
    for a in range(3):
        for b in range(a, 3):
            cov[:, a, b] = cov[:, b, a] = np.einsum("ij,ij->j", offsets[a], offsets[b]) / count - mean[a] * mean[b]
    return np.linalg.eigh(cov)[1][:, :, 0]


def refine_icp(source_xyz: np.ndarray, target_xyz: np.ndarray, initial: Transform, *,
               voxels_m: Sequence[float] = (0.20, 0.08, 0.04), max_iterations: int = 30,
               kernel_sigma_m: float | None = None, offset: np.ndarray | None = None,
               progress: ProgressCallback | None = None) -> IcpResult:
    """Refine ``initial`` (source -> target) by point-to-plane ICP with a Tukey kernel, coarse to fine.

    Parameters
    ----------
    source_xyz, target_xyz : (N, 3), (M, 3) float64 arrays, metres
        Points of the stable parts (piers, ground near them) in each epoch's frame.
    initial : Transform
        Starting transform, e.g. from :func:`registration.targets.register_targets`.
    voxels_m : sequence of float, keyword-only
        Voxel sizes of the levels, coarse to fine (default 20, 8, 4 cm): both clouds are reduced to their
        voxels' centroids. The correspondence distance at each level is 2.5 voxels; normals come from the
        30 nearest target points within 3 voxels (the 6 nearest where fewer lie that close).
    max_iterations : int, keyword-only
        Per level (default 30). A level ends sooner when the share of matched points and their RMS distance
        change by less than 1e-6 between iterations (Open3D's default criteria).
    kernel_sigma_m : float, optional
        Tukey kernel width; default one voxel at each level.
    offset : (3,) array, optional
        Subtracted from all coordinates before solving (default: the target's mean), so large
        project coordinates lose no precision.
    progress : callable, optional

    Returns
    -------
    IcpResult
    """
    src, tgt = check_clouds(source_xyz, target_xyz, "ICP")
    if not voxels_m or any(not (v > 0) for v in voxels_m):
        raise InputError("ICP voxel sizes must be positive")
    off = tgt.mean(axis=0) if offset is None else np.asarray(offset, dtype=np.float64)
    shift = Transform(np.eye(3), -off)
    # Work in reduced coordinates: source is moved by the initial transform and the offset.
    src_red, tgt_red = initial.then(shift).apply(src), tgt - off
    current = np.eye(4)
    iterations, level = [], None
    for k, v in enumerate(voxels_m):
        report(progress, k / len(voxels_m), f"ICP level {k + 1}/{len(voxels_m)} ({v * 100:.0f} cm)")
        level = _Level(voxel_centroids(src_red, v), voxel_centroids(tgt_red, v), v, kernel_sigma_m or v)
        current, count = level.solve(current, max_iterations)
        iterations.append(count)
    assert level is not None
    fitness, inlier_rms, plane_rms = level.quality(current)
    if fitness < 0.2:
        raise RegistrationError(f"ICP found correspondences for only {fitness:.0%} of the stable points; the "
                                "initial registration is too far off or the stable areas differ")
    corr_reduced = Transform.from_matrix(current)
    # correction in the target frame: x -> off + C (x - off)
    correction = shift.then(corr_reduced).then(shift.inverse())
    result = initial.then(correction)
    result = Transform(result.rotation, result.translation, result.scale, initial.source_frame, initial.target_frame,
                       initial.sigma_translation_m, initial.sigma_rotation_deg, f"{initial.method}+icp", initial.notes)
    report(progress, 1.0, "ICP done")
    return IcpResult(result, Transform(correction.rotation, correction.translation, 1.0, initial.target_frame,
                                       initial.target_frame, method="icp"),
                     fitness, inlier_rms, tuple(iterations), tuple(float(v) for v in voxels_m),
                     len(level.source), len(level.target), off, plane_rms)


#: Source points a level fits and scores at most (every k-th of its voxels, which lie in Z-order: spread
#: evenly); a larger cloud adds queries, not accuracy.
FIT_POINTS = 150_000


class _Level:
    """One resolution of the ICP: downsampled clouds, the target's tree and normals, the matching distance.

    Points match within 2.5 voxels; normals come from the 30 nearest target points within 3 voxels (the
    6 nearest where fewer lie that close), computed for the target points that are matched.
    """

    def __init__(self, source: np.ndarray, target: np.ndarray, voxel_m: float, kernel_m: float):
        self.source, self.max_distance_m, self.kernel_m = source, 2.5 * voxel_m, kernel_m
        self.fit_source = source[::-(-len(source) // FIT_POINTS)]
        # column-major: each call of surface_normals takes the target's columns as views, not copies
        self.target, self.radius_m = np.asfortranarray(target), 3.0 * voxel_m
        self.tree = cKDTree(target, balanced_tree=False, compact_nodes=False)
        self._normals = np.zeros((len(target), 3))
        self._known = np.zeros(len(target), bool)

    def normals(self, idx: np.ndarray) -> np.ndarray:
        """Normals at the target points ``idx`` (computed once each, when first needed)."""
        new = unique_sorted(idx[~self._known[idx]])
        if new.size:
            self._normals[new] = surface_normals(self.target, self.tree, radius_m=self.radius_m, which=new)
            self._known[new] = True
        return self._normals[idx]

    def match(self, matrix: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Moved ``points`` with a target point within the distance, that point's index, the distance."""
        moved = points @ matrix[:3, :3].T + matrix[:3, 3]
        dist, idx = self.tree.query(moved, distance_upper_bound=self.max_distance_m, workers=-1)
        ok = np.isfinite(dist)
        return moved[ok], idx[ok], dist[ok]

    def quality(self, matrix: np.ndarray) -> tuple[float, float, float]:
        """Share of source points matched, their RMS point distance and RMS point-to-plane distance (m)."""
        moved, idx, dist = self.match(matrix, self.fit_source)
        if not len(idx):
            return 0.0, float("nan"), float("nan")
        plane = np.einsum("ij,ij->i", moved - self.target[idx], self.normals(idx))
        return len(idx) / len(self.fit_source), _rms(dist), _rms(plane)

    def solve(self, matrix: np.ndarray, max_iterations: int) -> tuple[np.ndarray, int]:
        """Iterate the weighted point-to-plane step from ``matrix``; the refined matrix and the iterations run."""
        points = self.fit_source
        moved, idx, dist = self.match(matrix, points)
        before = (len(idx), _rms(dist))
        for it in range(1, max_iterations + 1):
            if len(idx) < 6:
                return matrix, it - 1
            matrix = _step(moved, self.target[idx], self.normals(idx), self.kernel_m) @ matrix
            moved, idx, dist = self.match(matrix, points)
            after = (len(idx), _rms(dist))
            if abs(after[0] - before[0]) < 1e-6 * len(points) and abs(after[1] - before[1]) < 1e-6:
                return matrix, it
            before = after
        return matrix, max_iterations


def _rms(values: np.ndarray) -> float:
    """Root mean square (0 of none)."""
    return float(np.sqrt(np.mean(values ** 2))) if len(values) else 0.0


def _step(moved: np.ndarray, matched: np.ndarray, normals: np.ndarray, kernel_m: float) -> np.ndarray:
    """The 4x4 update that minimises the Tukey-weighted point-to-plane residuals, linearised in the rotation."""
    residual = np.einsum("ij,ij->i", moved - matched, normals)
    u = residual / kernel_m
    weight = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
    jac = np.hstack([np.cross(moved, normals), normals])  # d residual / d (rotation vector, translation)
    wj = jac * weight[:, None]
    lhs = np.einsum("ni,nj->ij", wj, jac)
    rhs = -np.einsum("ni,n->i", wj, residual)
    try:
        x = np.linalg.solve(lhs, rhs)
    except np.linalg.LinAlgError:
        return np.eye(4)
    update = np.eye(4)
    update[:3, :3] = rotation_from_rotvec(x[:3])
    update[:3, 3] = x[3:]
    return update


def stable_mask(xyz: np.ndarray, anchors_xyz: np.ndarray, *, radius_m: float = 4.0,
                exclude_above_m: float | None = None, up: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
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

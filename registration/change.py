"""Change between two registered clouds: cloud-to-cloud distance and M3C2 (py4dgeo)."""
from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from common.imports import import_in_background
from common.progress import ProgressCallback, report
from common.validation import require_points
from registration.errors import InputError

METHODS = ("c2c", "m3c2")


@dataclass(frozen=True, eq=False)
class ChangeResult:
    """Distances from a reference cloud to a compared cloud, at ``points`` (campaign frame).

    Attributes
    ----------
    method : {"c2c", "m3c2"}
    points : (K, 3) float64 array, metres
        Where the change is given: the compared cloud's points (c2c) or the core points (m3c2).
    distance_m : (K,) float64 array
        c2c: unsigned nearest-neighbour distance; m3c2: signed distance along ``normals``
        (positive where the compared epoch lies on the normal's side). NaN where not computable.
    lod_m : (K,) float64 array or None
        M3C2 level of detection at 95 %, including the registration error.
    normals : (K, 3) array or None
    registration_error_m : float
    parameters : dict
    """

    method: str
    points: np.ndarray
    distance_m: np.ndarray
    lod_m: np.ndarray | None
    normals: np.ndarray | None
    registration_error_m: float
    parameters: dict

    @property
    def significant(self) -> np.ndarray:
        """(K,) bool: |distance| above the level of detection (c2c: above the registration error)."""
        lod = self.lod_m if self.lod_m is not None else np.full(len(self.distance_m), self.registration_error_m)
        with np.errstate(invalid="ignore"):
            return np.abs(self.distance_m) > lod

    def summary(self, mask: np.ndarray | None = None) -> dict:
        """Statistics over all points or a subset (mm)."""
        d = self.distance_m if mask is None else self.distance_m[mask]
        ok = np.isfinite(d)
        out: dict[str, float | None] = {"n": int(ok.sum())}
        if ok.any():
            dd = d[ok] * 1e3
            out.update(mean_mm=float(dd.mean()), median_mm=float(np.median(dd)), std_mm=float(dd.std()),
                       rms_mm=float(np.sqrt(np.mean(dd ** 2))), p95_abs_mm=float(np.percentile(np.abs(dd), 95)))
            if self.lod_m is not None:
                lod = (self.lod_m if mask is None else self.lod_m[mask])[ok] * 1e3
                out.update(median_lod_mm=float(np.nanmedian(lod)) if np.isfinite(lod).any() else None,
                           significant_share=float(np.mean(np.abs(dd) > lod)))
        return out


@contextlib.contextmanager
def _quiet_py4dgeo():
    """Quiet py4dgeo while we call it.

    py4dgeo logs every search tree at INFO and appends to ./py4dgeo.log in the user's folder: keep warnings only, and
    no log file, while we call it.
    """
    lg = logging.getLogger("py4dgeo")
    level = lg.level
    files = [h for h in lg.handlers if isinstance(h, logging.FileHandler)]
    lg.setLevel(logging.WARNING)
    for h in files:
        lg.removeHandler(h)
    try:
        yield
    finally:
        for h in files:
            lg.addHandler(h)
        lg.setLevel(level)


def prefetch_py4dgeo(*also: str) -> threading.Thread:
    """Start importing py4dgeo's compiled core, then the modules ``also``, while other work runs.

    :func:`m3c2` imports it as usual and waits for this import to finish, so it is imported once per process,
    and only by a job that runs M3C2 (see :func:`common.imports.import_in_background`).
    """
    return import_in_background(("_py4dgeo", *also))


class _CoreUnlike(Exception):
    """py4dgeo's compiled core is not the one :func:`_m3c2_compiled` was written for."""


def _m3c2_compiled(ref: np.ndarray, cmp_: np.ndarray, core: np.ndarray, radii: tuple[float, ...], cyl_radius: float,
                   max_distance: float, registration_error: float, robust_aggr: bool, orientation: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """py4dgeo's M3C2 by the calls its ``M3C2.run`` makes into its compiled core (``_py4dgeo``).

    Importing the package ``py4dgeo`` takes 1.3 s of a core (it imports scikit-learn, seaborn, pandas and
    scipy.stats for its other algorithms); its compiled core takes 3 ms and computes the same distances, levels
    of detection and normals to the bit (tested against ``py4dgeo.M3C2``). Raises :class:`_CoreUnlike` where
    the core lacks these calls (another py4dgeo): :func:`_m3c2_package` then does the work.
    """
    try:
        # local: a py4dgeo without this compiled core raises ImportError here, and the package does the work
        import _py4dgeo as core_lib

        epochs = []
        for cloud in (ref, cmp_):
            epoch = core_lib.Epoch(np.ascontiguousarray(cloud, dtype=np.float64))
            if epoch.get_default_radius_search_tree() == core_lib.SearchTree.KDTreeSearch:
                epoch._kdtree.build_tree(10)  # py4dgeo's Epoch.build_kdtree default leaf size
            else:
                epoch._octree.build_tree()
            epochs.append(epoch)
        core = np.ascontiguousarray(core, dtype=np.float64)
        normals, _ = core_lib.compute_multiscale_directions(epochs[0], core, list(radii), orientation)
        aggregate = core_lib.median_iqr_distance if robust_aggr else core_lib.mean_stddev_distance
        d, unc = core_lib.compute_distances(core, cyl_radius, epochs[0], epochs[1], normals, max_distance,
                                            registration_error, core_lib.cylinder_workingset_finder, aggregate)
        return d, unc["lodetection"], normals
    except (ImportError, AttributeError, TypeError, ValueError) as exc:
        raise _CoreUnlike(str(exc)) from exc


def _m3c2_package(ref: np.ndarray, cmp_: np.ndarray, core: np.ndarray, radii: tuple[float, ...], cyl_radius: float,
                  max_distance: float, registration_error: float, robust_aggr: bool, orientation: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """py4dgeo's M3C2 through its public API (see :func:`_m3c2_compiled`)."""
    # local: the package py4dgeo costs 1.3-1.7 s of start-up (scikit-learn, pandas; measured), the fallback only
    import py4dgeo

    with _quiet_py4dgeo():
        algo = py4dgeo.M3C2(epochs=(py4dgeo.Epoch(ref), py4dgeo.Epoch(cmp_)), corepoints=core,
                            normal_radii=list(radii), cyl_radius=cyl_radius, max_distance=max_distance,
                            registration_error=registration_error, robust_aggr=robust_aggr,
                            orientation_vector=orientation)
        d, unc = algo.run()
    return d, unc["lodetection"], algo.directions()


def _check(name: str, a) -> np.ndarray:
    return require_points(a, name)


def cloud_to_cloud(reference_xyz: np.ndarray, compared_xyz: np.ndarray, *, max_distance_m: float = 1.0,
                   registration_error_m: float = 0.0) -> ChangeResult:
    """Nearest-neighbour distance from every compared point to the reference cloud (unsigned, metres).

    Distances beyond ``max_distance_m`` (default 1 m: no counterpart) are NaN. A KD-tree of the reference
    answers the queries on every core (``workers=-1``). It is built without ``compact_nodes`` and
    ``balanced_tree``: cheaper to build, and a bounded query of points far from the reference (the ground
    beyond the bridge) no longer walks most of the tree (25 s instead of 1.5 s on two 1.2 M-point scans).
    Leaves of 32 points rather than 16: 0.47 -> 0.44 s on those scans, the build twice as quick.
    """
    ref = _check("reference cloud", reference_xyz)
    cmp_ = _check("compared cloud", compared_xyz)
    if not (np.isfinite(max_distance_m) and max_distance_m > 0):
        raise InputError(f"C2C max distance must be positive, got {max_distance_m}")
    off = ref.mean(axis=0)
    tree = cKDTree(ref - off, leafsize=32, balanced_tree=False, compact_nodes=False)
    d, _ = tree.query(cmp_ - off, distance_upper_bound=max_distance_m, workers=-1)
    d[~np.isfinite(d)] = np.nan
    return ChangeResult("c2c", cmp_, d, None, None, float(registration_error_m),
                        {"max_distance": max_distance_m, "registration_error": float(registration_error_m)})


def m3c2(reference_xyz: np.ndarray, compared_xyz: np.ndarray, core_points: np.ndarray, *,
         normal_radii: Sequence[float] = (0.5,), cyl_radius: float = 0.25, max_distance: float = 0.5,
         registration_error: float = 0.0, robust_aggr: bool = False,
         orientation: Sequence[float] = (0.0, 0.0, 1.0),
         progress: ProgressCallback | None = None) -> ChangeResult:
    """M3C2 distances (py4dgeo) at ``core_points`` with the level of detection.

    Parameters take py4dgeo's names and units (metres).

    Parameters
    ----------
    reference_xyz, compared_xyz : (N, 3), (M, 3) float64 arrays, metres, same frame
    core_points : (K, 3) array
        Where to measure (e.g. the reference cloud thinned to a grid, see :func:`core_points_grid`).
    normal_radii : sequence of float, keyword-only
        Radius of the normal estimate (default 0.5 m); several radii make it multi-scale (py4dgeo keeps,
        per core point, the radius whose neighbourhood is most planar).
    cyl_radius : float, keyword-only
        Projection cylinder radius (default 0.25 m).
    max_distance : float, keyword-only
        Cylinder half-length (default 0.5 m).
    registration_error : float, keyword-only
        Added to the level of detection (default 0).
    robust_aggr : bool, keyword-only
        Median and inter-quartile spread instead of mean and standard deviation (default False).
    orientation : (3,) sequence
        Normals are turned towards this direction (default up: positive distance = the surface rose).

    Returns
    -------
    ChangeResult
        ``lod_m`` is py4dgeo's ``lodetection``.
    """
    ref = _check("reference cloud", reference_xyz)
    cmp_ = _check("compared cloud", compared_xyz)
    core = _check("core points", core_points)
    radii = tuple(float(r) for r in np.atleast_1d(np.asarray(normal_radii, dtype=np.float64)))
    for name, v in (("normal radius", min(radii, default=float("nan"))), ("cylinder radius", cyl_radius),
                    ("max distance", max_distance)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"M3C2 {name} must be positive, got {v}")
    if not (np.isfinite(registration_error) and registration_error >= 0):
        raise InputError(f"M3C2 registration error must be zero or positive, got {registration_error}")
    off = ref.mean(axis=0)  # py4dgeo works in double, but reduced coordinates keep the search trees well-conditioned
    report(progress, 0.05, "M3C2: search trees and normals")
    args = (ref - off, cmp_ - off, core - off, radii, float(cyl_radius), float(max_distance), float(registration_error),
            bool(robust_aggr), np.asarray(orientation, dtype=np.float64))
    try:
        d, lod, normals = _m3c2_compiled(*args)
    except _CoreUnlike:
        d, lod, normals = _m3c2_package(*args)
    report(progress, 1.0, "M3C2 done")
    normals = np.asarray(normals, dtype=np.float64)
    return ChangeResult("m3c2", core, np.asarray(d, dtype=np.float64), np.asarray(lod, np.float64),
                        normals if normals.shape == core.shape else np.broadcast_to(normals, core.shape).copy(),
                        float(registration_error),
                        {"normal_radii": list(radii), "cyl_radius": float(cyl_radius),
                         "max_distance": float(max_distance), "registration_error": float(registration_error),
                         "robust_aggr": bool(robust_aggr), "corepoints": int(len(core))})


def core_points_grid(xyz: np.ndarray, spacing_m: float = 0.25) -> np.ndarray:
    """One point per occupied cube of ``spacing_m`` (the one nearest the cube's centre)."""
    xyz = _check("cloud", xyz)
    if not spacing_m > 0:
        raise InputError(f"core point spacing must be positive, got {spacing_m}")
    off = xyz.min(axis=0)
    scaled_xyz = (xyz - off) / spacing_m
    cell = np.floor(scaled_xyz).astype(np.int64)
    scaled_xyz -= cell
    scaled_xyz -= 0.5
    centre_dist = np.einsum("ij,ij->i", scaled_xyz, scaled_xyz)
    key = (cell[:, 0] * 1_000_003 + cell[:, 1]) * 1_000_033 + cell[:, 2]
    _, inv = np.unique(key, return_inverse=True)  # one sort of the cells
    inv = inv.reshape(-1)
    best = np.full(int(inv.max()) + 1, np.inf)
    np.minimum.at(best, inv, centre_dist)
    cand = np.flatnonzero(centre_dist == best[inv])  # the point nearest each cube's centre (ties: the first)
    _, first = np.unique(inv[cand], return_index=True)
    return xyz[cand[first]][np.argsort(inv[cand[first]], kind="stable")]

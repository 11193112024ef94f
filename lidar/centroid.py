"""Target centroids from fine scans: Otsu split, the one compact disc-sized cluster, honest covariance.

Real windows hold traps: a second bright object (a cable tie 45 mm away biased
a field result by millimetres), mixed pixels at the rim, saturated returns, a
target clipped by the window edge. The one disc is found by trimming
symmetrically around its centre in the disc's own plane, so anything brighter
than the threshold outside the disc cannot pull it; its range is the mean of its
points, and its place in its plane is the mean of every return around it weighted
by how much of the disc each beam saw (:func:`weighted_centre`), which the
threshold's in-or-out rim cannot give; each doubt is flagged.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal, overload

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from common.flags import (
    FLAG_CENTRES_APART,
    FLAG_CLIPPED,
    FLAG_FEW_POINTS,
    FLAG_GRAZING,
    FLAG_INCIDENCE_FROM_SCAN,
    FLAG_LOW_CONTRAST,
    FLAG_LOW_SEPARABILITY,
    FLAG_MOVED_DURING_SCAN,
    FLAG_NOT_COMPACT,
    FLAG_NOT_FOUND,
    FLAG_OFF_EXPECTED,
    FLAG_SATURATED,
    FLAG_SECOND_OBJECT,
    FLAG_SIZE,
    FLAG_TRANSIENT_REMOVED,
    FLAG_UNRESOLVED,
)
from lidar.angles import AngularWindow, direction_from_angles, spherical_from_xyz
from lidar.scanner_profile import VZ1000, ScannerProfile
from lidar.transients import window_motion

if TYPE_CHECKING:
    from lidar.plan import RoiPlan

#: A retro-reflector is several times brighter than its background; below this contrast
#: ((bright - dark) / (bright + dark) of the class means) the window holds no target.
MIN_CONTRAST = 0.3


@dataclass(frozen=True, eq=False)
class TargetCentroid:
    """Centroid of one target in one fine scan.

    Attributes
    ----------
    reflector : str
    xyz_socs : (3,) float64 array
        Centroid in the scanner frame, metres (NaN when not found).
    cov : (3, 3) float64 array
        Covariance of the centroid, m^2: range noise along the viewing direction
        divided by n, plus the in-plane term: the weighted centre's (the intensities'
        noise, and the rim's sampling as far as the weights are in or out), or the
        thresholded disc's rim sampling where the centre is not weighted.
    n_points : int
        Points averaged.
    threshold : float
        Otsu threshold on normalised intensity.
    separability : float
        Otsu's between-class / total variance ratio in [0, 1] (1 = perfectly bimodal).
    flags : tuple of str
        Doubts (see the FLAG_* constants); empty when all is well.
    n_window : int
        Points in the window.
    n_rejected_bright : int
        Bright points near the target that were not part of the disc.
    sigma_range_m : float
        Range noise measured from the disc's flatness.
    normal_socs : (3,) array
        Disc plane normal (towards the scanner).
    time_s : float
        Median time of the disc's points, seconds (NaN when the scan has no point times).
    time_span_s : float
        From the first to the last of the disc's points, seconds (NaN without point times).
    clipped_fraction : float
        Share of the disc's points at the window's intensity ceiling: a plateau there means the
        receiver clipped the target's returns.
    """

    reflector: str
    xyz_socs: np.ndarray
    cov: np.ndarray
    n_points: int
    threshold: float
    separability: float
    flags: tuple[str, ...]
    n_window: int
    n_rejected_bright: int = 0
    sigma_range_m: float = float("nan")
    normal_socs: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    time_s: float = float("nan")
    time_span_s: float = float("nan")
    clipped_fraction: float = 0.0

    @property
    def cos_incidence(self) -> float:
        """|cos| of the incidence: the disc's normal against the line of sight (NaN when unknown)."""
        n = np.asarray(self.normal_socs, dtype=np.float64)
        x = np.asarray(self.xyz_socs, dtype=np.float64)
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(x))) or not np.any(x):
            return float("nan")
        return float(abs(n @ x) / (np.linalg.norm(n) * np.linalg.norm(x)))

    @property
    def found(self) -> bool:
        return FLAG_NOT_FOUND not in self.flags

    @property
    def sigma_m(self) -> np.ndarray:
        """Standard deviations along the scanner axes, metres."""
        return np.sqrt(np.diag(self.cov))


def otsu_threshold(values: np.ndarray, bins: int = 256) -> tuple[float, float]:
    """Otsu's threshold and separability (between-class / total variance) of a sample."""
    v = np.asarray(values, dtype=np.float64)
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo:
        return hi, 0.0
    hist, edges = np.histogram(v, bins=bins, range=(lo, hi))
    centres = 0.5 * (edges[1:] + edges[:-1])
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centres)
    mt = m0[-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mt * w0 / w0[-1] - m0) ** 2 / (w0 * w1) * w0[-1]
    between = np.nan_to_num(between[:-1])
    k = int(np.argmax(between))
    # An empty gap between the classes is a plateau of equal scores: take its middle, not its first bin.
    end = k
    while end + 1 < between.size and between[end + 1] >= between[k] * (1 - 1e-12):
        end += 1
    total = float(np.var(v)) * v.size
    sep = float(between[k] / total) if total > 0 else 0.0
    return float(0.5 * (edges[k + 1] + edges[end + 1])), min(1.0, sep)


def _not_found(reflector: str, n_window: int, threshold=float("nan"), sep=0.0, extra=()) -> TargetCentroid:
    return TargetCentroid(reflector, np.full(3, np.nan), np.full((3, 3), np.nan), 0, threshold, sep,
                          (FLAG_NOT_FOUND, *extra), n_window)


def _clusters(pts: np.ndarray, eps: float) -> np.ndarray:
    # local: scipy.spatial: 0.07-0.09 s of scanners' and reflector list's start-up (measured)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    tree = cKDTree(pts)
    pairs = tree.query_pairs(eps, output_type="ndarray")
    n = len(pts)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) else \
        coo_matrix((n, n))
    return connected_components(graph, directed=False)[1]


def _plane(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre, normal and two in-plane axes of a target's points, in the scanner's frame (metres).

    A scanner's noise is in the range, along each beam; its angles are nearly exact. A total least-squares
    plane (the smallest principal axis) takes that noise as spread across the plane and tilts the normal
    away from the beam (|cos| of a 50 mm disc's incidence read 0.03-0.06 low under 5 mm range noise, more
    the steeper the incidence), which biases everything fitted on the incidence (the range walk). Here the
    plane ``n . x = d`` is fitted as ``1 / r_i = (n / d) . u_i`` over the beams' exact directions ``u_i``:
    only the response is noisy, so the normal is unbiased. Directions are taken in a frame about the mean
    beam for conditioning; a degenerate set falls back to the principal axis.
    """
    c = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    r = np.linalg.norm(pts, axis=1)
    normal = vt[2]
    if len(pts) >= 5 and np.all(r > 0):
        u = pts / r[:, None]
        e3 = u.mean(axis=0)
        e3 /= np.linalg.norm(e3)
        e1 = vt[0] - (vt[0] @ e3) * e3
        if np.linalg.norm(e1) > 1e-9:
            e1 /= np.linalg.norm(e1)
            frame = np.stack([e1, np.cross(e3, e1), e3])
            a, _, rank, _ = np.linalg.lstsq(u @ frame.T, 1.0 / r, rcond=None)
            if rank == 3 and np.all(np.isfinite(a)) and np.linalg.norm(a) > 0:
                normal = frame.T @ a / np.linalg.norm(a)
    a1 = vt[0] - (vt[0] @ normal) * normal
    if np.linalg.norm(a1) < 1e-9:
        a1 = vt[1] - (vt[1] @ normal) * normal
    a1 /= np.linalg.norm(a1)
    return c, normal, np.stack([a1, np.cross(normal, a1)])


@dataclass(frozen=True, eq=False)
class CentroidTrace:
    """How a centroid was found, for display: (N,) masks over the window's points.

    ``bright`` above Otsu's threshold, ``cluster`` the compact bright cluster kept, ``disc`` the points
    whose mean range is the centroid's (the cluster trimmed symmetrically around the centre in the disc
    plane; the centre in the plane is weighted over these and the darker returns around them).
    """

    bright: np.ndarray
    cluster: np.ndarray
    disc: np.ndarray

    @classmethod
    def empty(cls, n: int) -> CentroidTrace:
        return cls(np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool))


@overload
def target_centroid(xyz_socs: np.ndarray, intensity: np.ndarray, *, reflector: str = "",
                    expected_xyz: ArrayLike | None = None, diameter_m: float = 0.05,
                    window: AngularWindow | None = None, profile: ScannerProfile = VZ1000,
                    min_points: int = 30, time_s: np.ndarray | None = None,
                    incidence_cos: float | None = None,
                    trace: Literal[False] = False) -> TargetCentroid: ...


@overload
def target_centroid(xyz_socs: np.ndarray, intensity: np.ndarray, *, reflector: str = "",
                    expected_xyz: ArrayLike | None = None, diameter_m: float = 0.05,
                    window: AngularWindow | None = None, profile: ScannerProfile = VZ1000,
                    min_points: int = 30, time_s: np.ndarray | None = None,
                    incidence_cos: float | None = None,
                    trace: Literal[True]) -> tuple[TargetCentroid, CentroidTrace]: ...


def target_centroid(xyz_socs: np.ndarray, intensity: np.ndarray, *, reflector: str = "",
                    expected_xyz: ArrayLike | None = None, diameter_m: float = 0.05,
                    window: AngularWindow | None = None, profile: ScannerProfile = VZ1000,
                    min_points: int = 30, time_s: np.ndarray | None = None,
                    incidence_cos: float | None = None,
                    trace: bool = False) -> TargetCentroid | tuple[TargetCentroid, CentroidTrace]:
    """Robust centroid of the target in one fine-scan window.

    Stages: Otsu's split of the intensities (:func:`_bright`), the compact bright cluster nearest
    the expected position (:func:`_pick_cluster`), symmetric trimming in the disc plane
    (:func:`_trim_disc`), the covariance (:func:`_covariance`), the centre in the disc's plane from
    every return's intensity (:func:`weighted_centre`; not where another bright object is within the
    beam's blur of the disc; where it lands beyond :data:`WEIGHTED_AGREEMENT` rim sigmas from the thresholded
    centre its sigma covers the thresholded one) and the doubts (:func:`_doubts`).

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        Points of the window, scanner frame, metres.
    intensity : (N,) array
        Normalised intensity.
    reflector : str, keyword-only
    expected_xyz : (3,), optional, keyword-only
        Where the target should be (the plan's window centre at the planned range).
    diameter_m : float, keyword-only
        Target diameter. Default 0.05 m.
    window : AngularWindow, optional, keyword-only
        The scanned window, to flag a target clipped by its edge.
    profile : ScannerProfile, keyword-only
        Footprint model. Default VZ-1000.
    min_points : int, keyword-only
        Fewer disc points than this: not found. Default 30.
    time_s : (N,) float64 array, optional, keyword-only
        Each point's time (seconds); gives the centroid's ``time_s`` and ``time_span_s``.
    incidence_cos : float, optional, keyword-only
        The target's |cos| of incidence where it is known (the plan's, from the layout's normals); default
        the disc's own fitted plane, which few points at grazing incidence tilt.
    trace : bool, keyword-only
        Also return a :class:`CentroidTrace` (the masks of each stage, for display). Default False.

    Returns
    -------
    TargetCentroid, or (TargetCentroid, CentroidTrace) with ``trace=True``
        ``found`` is False with FLAG_NOT_FOUND when there is no usable disc.
    """
    xyz = np.asarray(xyz_socs, dtype=np.float64)
    inten = np.asarray(intensity, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or inten.shape != (xyz.shape[0],):
        raise InputError("target_centroid needs (N, 3) points and (N,) intensities")
    ok = np.isfinite(xyz).all(axis=1) & np.isfinite(inten)
    tr = CentroidTrace.empty(len(ok))
    options = dict(reflector=reflector, expected_xyz=expected_xyz, diameter_m=diameter_m, window=window,
                   profile=profile, min_points=min_points, incidence_cos=incidence_cos)
    result = _centroid_stages(xyz[ok], inten[ok], np.nonzero(ok)[0], tr, **options)
    if time_s is not None:
        t = np.asarray(time_s, dtype=np.float64)
        if t.shape != (xyz.shape[0],):
            raise InputError("target_centroid needs one time per point")
        if result.found:
            result, tr = _without_movement(xyz, inten, ok, t, result, tr, options)
    if time_s is not None and result.found:
        td = t[tr.disc]
        td = td[np.isfinite(td)]
        if td.size:
            result = replace(result, time_s=float(np.median(td)), time_span_s=float(np.ptp(td)))
    return (result, tr) if trace else result


#: A surface that moved more than this (metres) while more than half of a target was scanned: scan it again.
MAX_CORRECTED_M = 0.005


def _without_movement(xyz: np.ndarray, inten: np.ndarray, ok: np.ndarray, t: np.ndarray, result: TargetCentroid,
                      tr: CentroidTrace, options: dict) -> tuple[TargetCentroid, CentroidTrace]:
    """The centroid with the points scanned while the surface around the target moved (a train) put back.

    The background (everything but the bright points) shows the movement against time along the lines of sight
    (:func:`lidar.transients.window_motion`); a disc glued to that surface moved with it, so every point of the
    disturbed time is moved back along its line of sight by the background's departure at its time and the
    window measured again. What the correction may leave (the disc's outline seen through the moved surface, a
    target standing off the surface on a bracket) is added to the centroid's covariance along the line of
    sight: a quarter of the departure, for the share of the disc it touched. A movement larger than
    :data:`MAX_CORRECTED_M` over more than half of the disc is corrected all the same but warned: the window
    should be scanned again. A movement that touched none of the disc's points changes nothing.
    """
    motion = window_motion(xyz[ok], t[ok], exclude=tr.bright[ok])
    if not motion.checked or not motion.disturbed:
        return result, tr
    touched = ok & motion.contains(t)
    when = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in motion.disturbed)
    share = float(np.count_nonzero(touched & tr.disc)) / max(int(np.count_nonzero(tr.disc)), 1)
    if share == 0.0:
        return result, tr
    peak_m = abs(motion.peak_mm) * 1e-3
    moved = xyz.copy()
    r = np.linalg.norm(moved[ok], axis=1)
    back = motion.range_offset_m(t[ok])
    moved[ok] *= ((r - back) / r)[:, None]
    tr2 = CentroidTrace.empty(len(ok))
    again = _centroid_stages(moved[ok], inten[ok], np.nonzero(ok)[0], tr2, **options)
    if not again.found:
        flag = (f"{FLAG_MOVED_DURING_SCAN}: the surface around it moved by {1e3 * peak_m:.1f} mm at {when} "
                f"while {100 * share:.0f} % of its points were scanned")
        return replace(result, flags=tuple(result.flags) + (flag,)), tr
    view = again.xyz_socs / np.linalg.norm(again.xyz_socs)
    left = (0.25 * peak_m * share) ** 2
    severe = share > 0.5 and peak_m > MAX_CORRECTED_M
    flag = (f"{FLAG_MOVED_DURING_SCAN if severe else FLAG_TRANSIENT_REMOVED}: the surface around it moved by "
            f"{1e3 * peak_m:.1f} mm at {when} while {100 * share:.0f} % of its points were scanned; they were moved "
            "back")
    return replace(again, cov=again.cov + left * np.outer(view, view), flags=tuple(again.flags) + (flag,)), tr2


def _bright(inten: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Otsu's threshold, its separability and the indices above it."""
    thr, sep = otsu_threshold(inten)
    return thr, sep, np.nonzero(inten > thr)[0]


def _pick_cluster(pts: np.ndarray, rng: float, radius: float, window, expected, diameter_m: float,
                  min_points: int, n_bright: int) -> tuple[np.ndarray | None, float]:
    """The compact bright cluster nearest the expected position (largest first); also the point spacing.

    Clustering runs in the scanner's angular grid (scaled to metres at the target's range), where
    neighbours are one grid step apart whatever the incidence; on a grazing surface adjacent columns
    can be a centimetre apart in 3-D.
    """
    spacing = float(np.sqrt(np.pi * radius ** 2 / max(n_bright, 1)))
    t_b, p_b, _ = spherical_from_xyz(pts)
    t_c = float(np.median(t_b))
    p_c = float(np.median(p_b))
    uv = np.column_stack([np.radians(t_b - t_c) * rng,
                          np.radians(np.mod(p_b - p_c + 180.0, 360.0) - 180.0) * np.sin(np.radians(t_c)) * rng])
    if window is not None:
        gap = rng * np.radians(max(window.theta_step_deg, window.phi_step_deg * np.sin(np.radians(t_c))))
    else:
        gap = 2.0 * float(np.sqrt(np.prod(np.ptp(uv, axis=0) + 1e-6) / n_bright))
    eps = float(np.clip(2.5 * gap, 0.0005, 0.03))
    labels = _clusters(uv, eps)
    best, best_key = None, None
    for lab in np.unique(labels):
        members = np.nonzero(labels == lab)[0]
        if members.size < min_points:
            continue
        centre = np.median(pts[members], axis=0)
        dist = 0.0 if expected is None else float(np.linalg.norm(centre - expected))
        key = (dist > max(0.1, 3 * diameter_m), -members.size)
        if best_key is None or key < best_key:
            best, best_key = members, key
    return best, spacing


def _trim_disc(cluster: np.ndarray, axes: np.ndarray, r_trim: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre and kept-point mask of the cluster trimmed symmetrically around its centre in the disc plane."""
    centre = np.median(cluster, axis=0)
    keep = np.ones(len(cluster), bool)
    for _ in range(50):
        inplane = (cluster - centre) @ axes.T
        keep = np.einsum("ij,ij->i", inplane, inplane) <= r_trim ** 2
        new = cluster[keep].mean(axis=0)
        if np.linalg.norm(new - centre) < 1e-7:
            centre = new
            break
        centre = new
    return centre, keep


#: A disc whose projected short axis is narrower than this fraction of the beam's footprint is not measured:
#: its returns are all mixed pixels, its centroid off by more than :func:`grazing_variance` covers.
UNRESOLVED_RATIO = 0.2
#: Below this fraction (and above :data:`UNRESOLVED_RATIO`) a disc is *weak*: measured, flagged ``grazing``
#: with :func:`grazing_variance` (several millimetres along the line of sight), but planned only in the time
#: the budget leaves after every other window (:func:`lidar.plan.plan_fine_scans`).
WEAK_RATIO = 0.35
#: Below this fraction it is measured, flagged ``grazing``, with its range-direction sigma widened.
GRAZING_RATIO = 0.7


def resolvability(diameter_m: float, cos_incidence: float, range_m: float, profile: ScannerProfile) -> float:
    """The disc's projected short axis over the beam's footprint at its range (dimensionless).

    A 50 mm disc at 80 deg incidence is 9 mm wide across its short axis; at 50 m a VZ-1000's beam is
    22 mm wide: 0.4. Below :data:`UNRESOLVED_RATIO` every return is a mixed pixel and the centroid is off
    by millimetres along the line of sight; below :data:`GRAZING_RATIO` it is measured with
    :func:`grazing_variance` added.
    """
    return float(diameter_m * max(cos_incidence, 0.0) / max(float(profile.footprint_m(range_m)), 1e-4))


def resolved_share(flags: Sequence[str]) -> float:
    """The disc's width over the beam's (:func:`resolvability`) a centroid's ``grazing`` flag states; 1 without one."""
    for f in flags:
        if f.startswith(f"{FLAG_GRAZING}: the disc is "):
            try:
                return float(f.split("the disc is ", 1)[1].split(" %", 1)[0]) / 100.0
            except ValueError:
                return 0.0
    return 1.0


def is_weak(flags: Sequence[str]) -> bool:
    """Whether a centroid's flags say its disc was narrower than :data:`WEAK_RATIO` of the beam."""
    return resolved_share(flags) < WEAK_RATIO


def _deg(cos_incidence: float) -> float:
    return math.degrees(math.acos(min(max(cos_incidence, 0.0), 1.0)))


def apparent_cos(points: np.ndarray, view: np.ndarray, radius_m: float) -> float:
    """|cos| of a disc's incidence from its outline across the line of sight (0 when the beam hides it).

    The bright points of a disc of radius R seen at incidence i, projected on the plane across the line of
    sight ``view``, spread R^2/4 along its long axis and R^2 cos^2(i)/4 along its short one, each widened by
    the beam's blur. The disc's size is known, so the long axis measures the blur (its spread beyond R^2/4),
    which is taken off the short axis as well: a disc the beam does not resolve gives 0 rather than the rounder
    outline the blur draws. Unlike the disc's fitted plane, the outline uses only the points' directions, which
    range noise does not move.

    Parameters
    ----------
    points : (N, 3) float64
        The disc's bright points, scanner frame, metres.
    view : (3,) float64
        Unit vector along the line of sight.
    radius_m : float
        The disc's radius, metres.
    """
    v = np.asarray(view, dtype=np.float64)
    e1 = np.cross(v, [0.0, 0.0, 1.0] if abs(v[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(v, e1)
    p = np.asarray(points, dtype=np.float64)
    uv = (p - p.mean(axis=0)) @ np.stack([e1, e2]).T
    if len(uv) < 3:
        return 0.0
    short, long = np.linalg.eigvalsh(np.cov(uv.T))
    disc = radius_m ** 2 / 4.0
    blur = max(long - disc, 0.0)
    return float(np.sqrt(np.clip((short - blur) / disc, 0.0, 1.0)))


def grazing_variance(diameter_m: float, cos_incidence: float, ratio: float) -> float:
    """Range-direction variance (m^2) of a partly resolved disc's centroid: its rim's depth, by how unresolved.

    The disc spans ``D sin(incidence)`` in depth; mixed pixels at its near and far rims pull the centroid
    along the line of sight by a share of that, growing as the disc narrows against the beam.
    """
    if ratio >= GRAZING_RATIO:
        return 0.0
    depth = diameter_m * math.sqrt(max(0.0, 1.0 - cos_incidence ** 2))
    return (0.01 * depth * (GRAZING_RATIO / max(ratio, 1e-3)) ** 2) ** 2


def grazing_covariance(view: np.ndarray, normal: np.ndarray, *, diameter_m: float, cos_incidence: float,
                       footprint_m: float, ratio: float) -> np.ndarray:
    """(3, 3) covariance (m^2) a partly resolved disc adds to its centroid (zero from :data:`GRAZING_RATIO` up).

    Two forms of the rim's mixed pixels are covered: a range error along the line of sight ``view``
    (:func:`grazing_variance`), and the same amount along the disc's short projected axis in its own plane (a
    rim cut by the beam moves the centroid along the disc, not along the beam); and, across the beam along
    the disc's long axis, a share of the footprint growing as the disc narrows (1-4 mm for a disc a quarter
    of a 22 mm footprint, in our simulations).
    """
    if ratio >= GRAZING_RATIO:
        return np.zeros((3, 3))
    v = np.asarray(view, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    var = grazing_variance(diameter_m, cos_incidence, ratio)
    cov = var * np.outer(v, v)
    short = v - (v @ n) * n
    if np.linalg.norm(short) > 1e-9:
        short /= np.linalg.norm(short)
        cov += var * np.outer(short, short)
    across = np.cross(v, n)
    if np.linalg.norm(across) > 1e-9:
        across /= np.linalg.norm(across)
        sigma = 0.015 * footprint_m * (GRAZING_RATIO / max(ratio, 1e-3)) ** 2
        cov += sigma ** 2 * np.outer(across, across)
    return cov


def rim_variance(radius_m: float, n_points: float, spacing_m: float) -> float:
    """In-plane variance (m^2, per axis) of a disc centroid from its rim.

    Each of the ~2 pi R / spacing rim points is in or out (threshold noise, mixed pixels), moving the centroid by
    about R / n each.
    """
    n_rim = 2 * np.pi * radius_m / max(spacing_m, 1e-4)
    return (radius_m / n_points) ** 2 * n_rim / 6.0


#: What a weighted centre's error across the line of sight holds beyond its weights' noise, metres (per axis in
#: the disc's plane): on the field-effects campaigns (drift during a window, clipped and walking returns) the
#: pier targets' error across the line of sight was 1.3-1.6 times the noise term alone (0.044-0.056 mm against
#: 0.027-0.042 mm); with this floor it is 0.6-1.1 times its sigma (five campaigns, clean, all effects, air).
WEIGHTED_FLOOR_M = 0.035e-3
#: The background beyond the blur's half width may pull the weighted centre by this many of its noise sigmas at
#: most; more, it is uneven on one side (a bracket's arm, a stain) and the thresholded centre is kept.
UNEVEN_PULL = 4.0
#: The weighted and the thresholded centres should lie within this many of the thresholded centre's in-plane
#: sigmas (its rim's, :func:`rim_variance`) of each other; farther apart, the weighted centre is kept and its
#: in-plane sigma widened to cover the thresholded one. On 573 windows of the field-effects campaigns (clean,
#: all effects, step walk, an imported air series, the amplitude intensity model) the weighted centre was
#: 0.046 mm off across the line of sight (RMS), the thresholded one 0.129 mm. They were more than 3 rim sigmas
#: apart in 8.4 % of the windows, and the weighted centre was the nearer in 46 of those 48 (the other two 0.11
#: and 0.12 mm off where the thresholded was 0.10 and 0.05); more than 5 apart in 0.9 %, the weighted the nearer
#: in all 5. Keeping the thresholded centre beyond 3 rim sigmas, as before, put 0.15-0.5 mm errors across the
#: line of sight with a sigma of 0.04-0.1 mm on pier targets. What the other guards (a crowded disc, the ring's
#: sectors, :data:`UNEVEN_PULL`) miss and pulls the weighted centre still lands inside its sigma.
WEIGHTED_AGREEMENT = 5.0


@dataclass(frozen=True, eq=False)
class WeightedCentre:
    """A disc's centre in its plane from every return's intensity, with its in-plane covariance.

    Attributes
    ----------
    xyz_socs : (3,) float64 array
        The centre, scanner frame, metres (on the disc's plane through its points' mean).
    cov_plane : (3, 3) float64 array
        Its covariance in the disc's plane, m^2 (rank 2).
    n_points : int
        Returns weighed (the disc, its rim and the background ring around it).
    weight_sigma : float
        The weights' noise (the background's intensity scatter over the disc's contrast).
    binary_share : float
        Share of the returns about the disc's edge whose weights are in or out (0 or capped): where the target
        saturates the receiver the rim is sampled in or out again, and the centre keeps that share of the rim term.
    """

    xyz_socs: np.ndarray
    cov_plane: np.ndarray
    n_points: int
    weight_sigma: float
    binary_share: float


def weighted_centre(xyz_socs: np.ndarray, intensity: np.ndarray, *, start_socs: np.ndarray, plane_point: np.ndarray,
                    normal: np.ndarray, axes: np.ndarray, radius_m: float, blur_m: float,
                    iterations: int = 4) -> WeightedCentre | None:
    """The disc's centre from every return near it, each weighted by how much of the disc its beam saw.

    A thresholded disc takes each rim return whole or not at all: which of the ~2 pi R / spacing rim returns
    pass is the aliasing of the scanner's grid on the disc's edge, 0.07-0.1 mm in the disc's plane at
    1,000 points. A mixed return's intensity says how much of its footprint was on the disc, so the mean of
    the returns weighted by ``(I - background) / (disc - background)`` (capped at 1) is the centre of the disc
    blurred by the beam, whichever the grid. The weights depend only on how much of the disc each beam saw, so
    any intensity model that grows with it (clipped at a ceiling, saturating, a retro-reflector's brightness
    at a steep view) gives the same centre. The background is a plane in intensity fitted on a ring beyond the
    blur; the disc's level is the lower quartile of its core (a clipped plateau on part of the core weighs no
    more than the rest). Returns are placed on the disc's plane along their beams, so their range noise does
    not move them in the plane.

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        The window's returns that may weigh: the disc's and every darker one (other bright objects left out),
        scanner frame, metres.
    intensity : (N,) float64 array
        Their normalised intensities.
    start_socs : (3,) float64 array, keyword-only
        A first centre (the thresholded one), metres.
    plane_point, normal : (3,) float64 arrays, keyword-only
        The disc's plane: a point on it and its unit normal.
    axes : (2, 3) float64 array, keyword-only
        Two orthonormal axes in the plane.
    radius_m : float, keyword-only
        The disc's radius, metres.
    blur_m : float, keyword-only
        The beam's footprint on the disc's plane, metres: returns up to ``radius_m + blur_m`` from the centre weigh.
    iterations : int, keyword-only
        Re-centrings of the weighed region. Default 4.

    Returns
    -------
    WeightedCentre, or None where the disc's core or the ring around it holds too few returns or too little
    contrast (the window's edge, a grazing view), or where the background beyond the blur's half width pulls the
    centre to one side by more than :data:`UNEVEN_PULL` of its noise sigmas (a bracket's arm, a stain).
    """
    xyz = np.asarray(xyz_socs, dtype=np.float64)
    inten = np.asarray(intensity, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or inten.shape != (xyz.shape[0],) or iterations < 1:
        raise InputError("weighted_centre needs (N, 3) returns, (N,) intensities and at least one iteration")
    dirs = xyz / np.linalg.norm(xyz, axis=1)[:, None]
    den = dirs @ normal
    ok = np.abs(den) > 0.05
    along = np.where(ok, (normal @ plane_point) / np.where(ok, den, 1.0), np.nan)
    rel = (along[:, None] * dirs - plane_point) @ axes.T
    ok &= np.all(np.isfinite(rel), axis=1)
    c2 = (np.asarray(start_socs, dtype=np.float64) - plane_point) @ axes.T
    for _ in range(iterations):
        r = np.where(ok, np.hypot(rel[:, 0] - c2[0], rel[:, 1] - c2[1]), np.inf)
        core = r < max(radius_m - blur_m / 2, 0.5 * radius_m)
        ring = (r > radius_m + blur_m) & (r < radius_m + 2 * blur_m + 0.01)
        sector = np.floor(np.arctan2(rel[ring, 1] - c2[1], rel[ring, 0] - c2[0]) / (np.pi / 8)).astype(int) % 16
        if np.count_nonzero(core) < 10 or np.bincount(sector, minlength=16).min() < 3:
            return None  # no background all round: the window's edge, where the blur may be cut on one side
        design = np.column_stack([np.ones(np.count_nonzero(ring)), rel[ring] - c2])
        coef, *_ = np.linalg.lstsq(design, inten[ring], rcond=None)
        level = float(np.percentile(inten[core], 25))
        contrast = level - float(coef[0])
        if contrast < 0.05:
            return None
        sel = r <= radius_m + blur_m
        w = np.minimum((inten[sel] - coef[0] - (rel[sel] - c2) @ coef[1:]) / contrast, 1.0)
        total = float(w.sum())
        if total <= 0:
            return None
        c2 = (w @ rel[sel]) / total
    scatter = float(np.std(inten[ring] - design @ coef, ddof=3)) / contrast
    d = rel[sel] - c2
    # Beyond the blur's half width a beam sees no disc: what weighs there is the background's unevenness (a bracket,
    # a stain), which pulls the centre to one side. Its pull against the weights' noise there: too strong, no centre.
    outer = np.hypot(d[:, 0], d[:, 1]) > radius_m + blur_m / 2
    pull = (w[outer] @ d[outer]) / total
    pull_sigma = scatter * math.sqrt(float(np.sum(d[outer] ** 2)) / 2) / total
    if np.any(outer) and float(np.hypot(*pull)) > UNEVEN_PULL * pull_sigma:
        return None
    free = w < 1.0  # a weight at its cap does not move with the noise
    cov2 = scatter ** 2 * (d[free].T @ d[free]) / total ** 2 + WEIGHTED_FLOOR_M ** 2 * np.eye(2)
    edge = np.abs(np.hypot(d[:, 0], d[:, 1]) - radius_m) <= blur_m / 2
    binary = float(np.mean((w[edge] >= 0.98) | (w[edge] <= 0.02))) if np.any(edge) else 1.0
    return WeightedCentre(plane_point + c2 @ axes, axes.T @ cov2 @ axes, int(np.count_nonzero(sel)), scatter,
                          binary)


def _covariance(disc: np.ndarray, view: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """(cov, sigma_range, disc normal, in-plane axes) of a disc's points.

    ``cov`` is the range noise along the view over n; the caller adds the in-plane term (the thresholded rim's,
    :func:`rim_variance`, or the weighted centre's).
    """
    n = len(disc)
    c_plane, normal2, axes2 = _plane(disc)
    if normal2 @ view < 0:
        normal2 = -normal2
    resid = (disc - c_plane) @ normal2
    dirs = disc / np.linalg.norm(disc, axis=1)[:, None]
    mean_dir = dirs.mean(axis=0)
    mean_dir /= np.linalg.norm(mean_dir)
    cos_a = max(abs(float(normal2 @ mean_dir)), 0.1)
    sigma_r = float(np.std(resid, ddof=3) / cos_a)
    cov = sigma_r ** 2 / n * np.outer(mean_dir, mean_dir)
    return cov, sigma_r, normal2, axes2


#: Bright returns beside a disc that count as a second object: a share of the disc's points, and at grazing views
#: (the disc narrower than :data:`GRAZING_RATIO` of the beam) a larger one. A grazing disc's smeared rim leaves 4-14 %
#: of stray bright returns beside the disc in our simulations of 30-70 m views, which the centroid leaves out and σ
#: carries; a cable tie 10 x 50 mm beside a 50 mm disc leaves about 23 %.
SECOND_OBJECT_SHARE = 0.03
SECOND_OBJECT_SHARE_GRAZING = 0.18


def _doubts(*, n: int, rejected: int, sep: float, saturated: int, rms_r: float, radius: float, footprint: float,
            centre, expected, diameter_m: float, window, disc: np.ndarray, grazing: bool = False) -> list[str]:
    flags = []
    if rejected > max(5, (SECOND_OBJECT_SHARE_GRAZING if grazing else SECOND_OBJECT_SHARE) * n):
        flags.append(FLAG_SECOND_OBJECT)
    if n < 100:
        flags.append(FLAG_FEW_POINTS)
    if sep < 0.6:
        flags.append(FLAG_LOW_SEPARABILITY)
    if saturated > 0.2 * n:
        flags.append(f"{FLAG_SATURATED}: {100.0 * saturated / n:.0f} % of the target's points at the intensity "
                     "ceiling")
    if not 0.6 * radius / np.sqrt(2) <= rms_r <= 1.4 * (radius + footprint / 2) / np.sqrt(2):
        flags.append(FLAG_SIZE)
    if expected is not None and np.linalg.norm(centre - expected) > max(0.05, 1.5 * diameter_m):
        flags.append(FLAG_OFF_EXPECTED)
    if window is not None:
        t, p, _ = spherical_from_xyz(disc)
        tol_t, tol_p = 1.5 * window.theta_step_deg, 1.5 * window.phi_step_deg
        p_rel = np.mod(p - window.phi_min_deg, 360.0)
        width = window.phi_max_deg - window.phi_min_deg
        if (t.min() < window.theta_min_deg + tol_t or t.max() > window.theta_max_deg - tol_t
                or p_rel.min() < tol_p or p_rel.max() > width - tol_p):
            flags.append(FLAG_CLIPPED)
    return flags


def _centroid_stages(xyz: np.ndarray, inten: np.ndarray, ok_idx: np.ndarray, tr: CentroidTrace, *, reflector,
                     expected_xyz, diameter_m, window, profile, min_points, incidence_cos=None) -> TargetCentroid:
    n_window = len(xyz)
    if n_window < min_points:
        return _not_found(reflector, n_window)
    thr, sep, bright = _bright(inten)
    tr.bright[ok_idx[bright]] = True
    if bright.size < min_points:
        return _not_found(reflector, n_window, thr, sep)
    hi, lo = float(inten[bright].mean()), float(inten[inten <= thr].mean()) if bright.size < n_window else 0.0
    if (hi - lo) / max(hi + lo, 1e-9) < MIN_CONTRAST:
        return _not_found(reflector, n_window, thr, sep, (FLAG_LOW_CONTRAST,))
    radius = diameter_m / 2
    pts = xyz[bright]
    rng = float(np.median(np.linalg.norm(pts, axis=1)))
    expected = None if expected_xyz is None else np.asarray(expected_xyz, dtype=np.float64)
    best, spacing = _pick_cluster(pts, rng, radius, window, expected, diameter_m, min_points, bright.size)
    if best is None:
        return _not_found(reflector, n_window, thr, sep)
    cluster = pts[best]
    _, normal, axes = _plane(cluster)
    view = -cluster.mean(axis=0) / np.linalg.norm(cluster.mean(axis=0))
    if normal @ view < 0:
        normal = -normal
    cos_inc = float(abs(normal @ view))
    cos_known = cos_inc if incidence_cos is None else float(incidence_cos)
    seen = apparent_cos(cluster, view, radius)
    disagrees = incidence_cos is not None and resolvability(diameter_m, seen, rng, profile) >= GRAZING_RATIO \
        and seen > 2.0 * cos_known
    if disagrees:  # the disc's outline says it is resolved where the layout's normal says it grazes: the scan wins
        cos_known = seen
    ratio = resolvability(diameter_m, cos_known, rng, profile)
    if ratio < UNRESOLVED_RATIO:
        return _not_found(reflector, n_window, thr, sep, (
            f"{FLAG_UNRESOLVED}: the disc is {100 * ratio:.0f} % of the beam's width at {rng:.0f} m and "
            f"{math.degrees(math.acos(min(cos_known, 1.0))):.0f} deg incidence",))
    footprint = profile.footprint_m(rng) / np.sqrt(max(cos_inc, 0.1))
    r_trim = radius + float(np.clip(footprint / 2, 0.002, 0.012))
    centre, keep = _trim_disc(cluster, axes, r_trim)
    disc = cluster[keep]
    n = len(disc)
    tr.cluster[ok_idx[bright[best]]] = True
    tr.disc[ok_idx[bright[best[keep]]]] = True
    if n < min_points:
        return _not_found(reflector, n_window, thr, sep)
    cov, sigma_r, normal2, axes2 = _covariance(disc, view)
    weighable = np.ones(n_window, bool)
    weighable[bright] = False
    weighable[bright[best]] = True  # the disc's returns and every darker one
    others = np.delete(pts, best, axis=0)
    crowded = others.size and np.any(np.linalg.norm(others - centre, axis=1) <= radius + 2 * footprint)
    rim = rim_variance(radius, n, spacing)
    apart_note = ""
    weighed = None if crowded else weighted_centre(  # a bright object near the disc would weigh on one side
        xyz[weighable], inten[weighable], start_socs=centre, plane_point=disc.mean(axis=0), normal=normal2,
        axes=axes2, radius_m=radius, blur_m=footprint)
    in_plane = axes2.T @ axes2
    if weighed is None:
        cov = cov + rim * in_plane
    else:
        apart = float(np.linalg.norm((weighed.xyz_socs - centre) @ axes2.T))
        centre = weighed.xyz_socs
        cov = cov + weighed.binary_share * rim * in_plane + weighed.cov_plane
        if apart > WEIGHTED_AGREEMENT * math.sqrt(rim):  # one of the two is pulled: sigma covers either
            cov = cov + apart ** 2 / 2 * in_plane
            apart_note = f"{FLAG_CENTRES_APART}: {1e3 * apart:.2f} mm apart"
    graze = grazing_variance(diameter_m, cos_known, ratio)
    if graze > 0:
        cov = cov + grazing_covariance(view, normal2, diameter_m=diameter_m, cos_incidence=cos_known,
                                       footprint_m=float(profile.footprint_m(rng)), ratio=ratio)
    near = np.linalg.norm(pts - centre, axis=1) <= 3 * diameter_m
    rejected = int(np.count_nonzero(near)) - n
    if rejected > 2 * n:  # a bright surface, not a disc: the disc is only a cut-out of it
        return _not_found(reflector, n_window, thr, sep, (FLAG_NOT_COMPACT,))
    top = float(inten.max())
    saturated = int(np.count_nonzero(inten[bright][best][keep] >= top - 1e-6))
    clipped = saturated / n if saturated >= max(5, 0.05 * n) else 0.0  # a plateau at the ceiling, not one point
    rms_r = float(np.sqrt(np.mean(np.sum(((disc - centre) @ axes2.T) ** 2, axis=1))))
    flags = _doubts(n=n, rejected=rejected, sep=sep, saturated=saturated, rms_r=rms_r, radius=radius,
                    footprint=footprint, centre=centre, expected=expected, diameter_m=diameter_m, window=window,
                    disc=disc, grazing=graze > 0)
    if graze > 0:
        flags.append(f"{FLAG_GRAZING}: the disc is {100 * ratio:.0f} % of the beam's width")
    if apart_note:
        flags.append(apart_note)
    if disagrees:
        flags.append(f"{FLAG_INCIDENCE_FROM_SCAN}: the disc's outline shows {_deg(seen):.0f} deg of incidence where "
                     f"the layout's normal predicts {_deg(float(incidence_cos)):.0f} deg; the scan's is used (check "
                     "the target's normal in the layout)")
    return TargetCentroid(reflector, centre, cov, n, thr, sep, tuple(flags), n_window, max(0, rejected),
                          sigma_r, normal2, clipped_fraction=float(clipped))


def centroids_from_scan(xyz_socs: np.ndarray, intensity: np.ndarray, rois: Sequence[RoiPlan], *,
                        diameters_m: Mapping[str, float] | None = None, profile: ScannerProfile = VZ1000,
                        time_s: np.ndarray | None = None) -> dict[str, TargetCentroid]:
    """Centroids of every planned target from the fine-scan points of one set-up (closure windows left out).

    See :func:`measure_windows`, which also measures the plan's closure windows.
    """
    return measure_windows(xyz_socs, intensity, rois, diameters_m=diameters_m, profile=profile, time_s=time_s)[0]


#: Points of one window more than this apart in time belong to different passes (the closure scans the first
#: target's window again at the end of the visit), seconds.
PASS_GAP_S = 5.0


def _passes(mask: np.ndarray, time_s: np.ndarray | None) -> list[np.ndarray]:
    """The window's points split into passes by gaps in their times (one pass without times)."""
    idx = np.nonzero(mask)[0]
    if time_s is None or idx.size == 0:
        return [idx]
    t = time_s[idx]
    if not np.all(np.isfinite(t)):
        return [idx]
    order = np.argsort(t, kind="stable")
    cuts = np.nonzero(np.diff(t[order]) > PASS_GAP_S)[0] + 1
    return [np.sort(part) for part in np.split(idx[order], cuts)]


def measure_windows(xyz_socs: np.ndarray, intensity: np.ndarray, rois: Sequence[RoiPlan], *,
                    diameters_m: Mapping[str, float] | None = None, profile: ScannerProfile = VZ1000,
                    time_s: np.ndarray | None = None
                    ) -> tuple[dict[str, TargetCentroid], dict[str, TargetCentroid]]:
    """Centroids of every planned target, and of the targets the plan scans again at its end (its closure).

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        All fine-scan points of the set-up (one or many windows).
    intensity : (N,) array
    rois : sequence of RoiPlan
        The plan's windows; each point is used by every window it falls in. A closure window
        (``roi.closure``) covers a window scanned earlier: with point times, the window's points
        split into passes by time and the first pass is the target's, the last its closure's.
    diameters_m : mapping reflector -> diameter, optional, keyword-only
        Default 0.05 m each.
    profile : ScannerProfile, keyword-only
    time_s : (N,) float64 array, optional, keyword-only
        Point times (seconds); without them a closure window cannot be told from its first pass and
        is not measured.

    Returns
    -------
    (centroids, closures) : dicts reflector -> TargetCentroid
    """
    theta, phi, _ = spherical_from_xyz(np.asarray(xyz_socs), out_dtype=np.float32)
    times = None if time_s is None else np.asarray(time_s, dtype=np.float64)
    repeated = {r.reflector for r in rois if getattr(r, "closure", False)}
    out: dict[str, TargetCentroid] = {}
    closures: dict[str, TargetCentroid] = {}
    for roi in rois:
        is_closure = bool(getattr(roi, "closure", False))
        mask = roi.window.contains(theta, phi)
        if roi.reflector in repeated:
            passes = _passes(mask, times)
            if len(passes) < 2:
                if is_closure:
                    continue  # no times, or no second pass: the closure is not told apart from the first
                sel = passes[0]
            else:
                sel = passes[-1] if is_closure else passes[0]
        else:
            sel = np.nonzero(mask)[0]
        tc, pc = roi.window.centre
        expected = direction_from_angles(tc, pc) * roi.range_m
        d = 0.05 if diameters_m is None else float(diameters_m.get(roi.reflector, 0.05))
        inc = math.cos(math.radians(roi.incidence_deg)) if math.isfinite(roi.incidence_deg) else None
        c = target_centroid(xyz_socs[sel], intensity[sel], reflector=roi.reflector, expected_xyz=expected,
                            diameter_m=d, window=roi.window, profile=profile,
                            time_s=None if times is None else times[sel], incidence_cos=inc)
        (closures if is_closure else out)[roi.reflector] = c
    return out, closures

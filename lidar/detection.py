"""Reflector detection on a reflectance map: bright compact blobs of a target's angular size."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.arrays import median
from common.errors import InputError
from lidar.reflectance_map import ReflectanceMap


@dataclass(frozen=True)
class Detection:
    """A bright blob that may be a reflector.

    Attributes
    ----------
    theta_deg, phi_deg : float
        Intensity-weighted blob centre (phi in [0, 360)).
    range_m : float
        Mean range of the blob's cells.
    xyz_socs : (3,) tuple of float
        Approximate 3-D position in the scanner frame, metres.
    peak_intensity : float
    n_cells : int
    size_deg : float
        Largest angular extent of the blob (azimuth extent scaled by sin(theta)).
    expected_size_deg : float
        Angular diameter of a face-on target of the campaign's diameter at this range.
    score : float
        In (0, 1]: brightness times agreement of size with the expected one.
    guided : bool
        Found by the guided second look at a position the layout predicts
        (:func:`recover_predicted`), not by the blob search.
    """

    theta_deg: float
    phi_deg: float
    range_m: float
    xyz_socs: tuple[float, ...]
    peak_intensity: float
    n_cells: int
    size_deg: float
    expected_size_deg: float
    score: float
    guided: bool = False


@dataclass(frozen=True)
class DetectionResult:
    """Detections (best score first), blobs rejected as too large, and the threshold used."""

    detections: tuple[Detection, ...]
    rejected: tuple[Detection, ...]
    threshold: float
    map_step_deg: float

    def xyz(self) -> np.ndarray:
        return np.array([d.xyz_socs for d in self.detections], dtype=np.float64).reshape(-1, 3)


def auto_threshold(values: np.ndarray) -> float:
    """Brightness threshold separating retro-reflectors from the background of a map.

    Halfway between the background median and the brightest cell, but at least
    3 robust standard deviations above the background median.
    """
    a = np.asarray(values)
    top = float(np.fmax.reduce(a, axis=None)) if a.size else np.nan  # NaN cells left out, no mask made
    if not np.isfinite(top):  # every cell NaN, or infinite values: the largest finite one
        finite = np.isfinite(a)
        if not finite.any():
            raise InputError("the reflectance map is empty")
        top = float(np.max(a, where=finite, initial=-np.inf))
    # the background statistics need no more than about a million cells: a strided view of the map (a
    # large map's views are not contiguous, and a flat copy of one cost more than the statistics)
    k = max(int(np.sqrt(a.size / 1_000_000)), 1) if a.ndim == 2 else 1
    sample = a[::k, ::k] if a.ndim == 2 else a
    v = sample[np.isfinite(sample)]
    if v.size == 0:
        v = a[np.isfinite(a)]
    if not np.issubdtype(v.dtype, np.floating):
        v = v.astype(np.float64)
    bg = median(v)
    np.subtract(v, bg, out=v)  # v is the sample's own copy (boolean indexing): |v - bg| is made in it
    np.abs(v, out=v)
    mad = median(v, overwrite_input=True) * 1.4826
    return max(bg + 3.0 * mad, bg + 0.5 * (top - bg))


def detect_reflectors(rmap: ReflectanceMap, *, target_diameter_m: float = 0.05, threshold: float | None = None,
                      footprint_mrad: float = 0.3, max_size_factor: float = 1.6) -> DetectionResult:
    """Find reflector candidates in a reflectance map.

    Parameters
    ----------
    rmap : ReflectanceMap
    target_diameter_m : float, keyword-only
        Diameter of the campaign's targets. Default 0.05 m.
    threshold : float, optional, keyword-only
        Normalised intensity threshold; default :func:`auto_threshold`.
    footprint_mrad : float, keyword-only
        Beam divergence: blobs grow by the footprint at their range. Default 0.3 mrad.
    max_size_factor : float, keyword-only
        A blob larger than this factor times (expected size + footprint + 2 cells) is
        rejected as not a target (a sign, a vest, a window). Default 1.6.

    Returns
    -------
    DetectionResult
    """
    if not (np.isfinite(target_diameter_m) and target_diameter_m > 0):
        raise InputError(f"target diameter must be positive, got {target_diameter_m}")
    # Work on the transposed (azimuth-major) view: blobs are numbered in the order of their first cell by
    # azimuth, then zenith.
    img = rmap.max_intensity.T
    thr = auto_threshold(img) if threshold is None else float(threshold)
    runs = component_runs(img >= thr)  # NaN (empty cells) compares False
    if runs.n == 0:
        return DetectionResult((), (), thr, rmap.step_deg)
    w = runs.shape[0]  # (columns, rows)
    cols, rows, lab = runs.cells()  # the bright cells only, in the transposed view's row-major order
    if rmap.full_circle:
        roots, col_shift = _merge_across_seam(runs.line(0), runs.line(w - 1), runs.n, w)
        cols = cols + col_shift[lab]  # seam-merged blobs continue past the last column
        lab = roots[lab]
    vals = img[cols % w, rows]
    weight = vals - thr * 0.9
    nlab = int(lab.max()) + 1
    sw = np.bincount(lab, weight, nlab)
    n_cells = np.bincount(lab, minlength=nlab)
    r_c = np.bincount(lab, weight * rows, nlab) / np.where(sw > 0, sw, 1)
    c_c = np.bincount(lab, weight * cols, nlab) / np.where(sw > 0, sw, 1)
    rng_vals = np.nan_to_num(rmap.range_m.T[cols % w, rows], nan=0.0)
    valid_r = rng_vals > 0
    rng = np.bincount(lab, rng_vals * valid_r, nlab) / np.maximum(np.bincount(lab, valid_r.astype(float), nlab), 1)
    peak = np.zeros(nlab)
    np.maximum.at(peak, lab, vals)
    row_lo = np.full(nlab, np.inf)
    row_hi = np.full(nlab, -np.inf)
    col_lo = np.full(nlab, np.inf)
    col_hi = np.full(nlab, -np.inf)
    np.minimum.at(row_lo, lab, rows)
    np.maximum.at(row_hi, lab, rows)
    np.minimum.at(col_lo, lab, cols)
    np.maximum.at(col_hi, lab, cols)
    theta, phi = rmap.cell_angles(r_c, c_c)
    sin_t = np.sin(np.radians(theta))
    size = np.maximum(row_hi - row_lo + 1, (col_hi - col_lo + 1) * sin_t) * rmap.step_deg
    kept: list[Detection] = []
    rejected: list[Detection] = []
    for k in range(1, nlab):
        if n_cells[k] == 0 or rng[k] <= 0:
            continue
        expected = float(np.degrees(target_diameter_m / rng[k]))
        footprint = float(np.degrees(footprint_mrad * 1e-3 + 0.007 / rng[k]))
        allowed = max_size_factor * (expected + footprint + 2 * rmap.step_deg)
        fit = float(np.exp(-(max(0.0, size[k] - expected - footprint) / (expected + rmap.step_deg)) ** 2))
        det = Detection(
            theta_deg=float(theta[k]), phi_deg=float(phi[k]), range_m=float(rng[k]),
            xyz_socs=tuple(float(v) for v in rmap.xyz_of(theta[k], phi[k], rng[k])),
            peak_intensity=float(peak[k]), n_cells=int(n_cells[k]), size_deg=float(size[k]),
            expected_size_deg=expected, score=float(min(1.0, peak[k]) * fit),
        )
        (kept if size[k] <= allowed else rejected).append(det)
    kept.sort(key=lambda d: -d.score)
    return DetectionResult(tuple(kept), tuple(rejected), thr, rmap.step_deg)


@dataclass(frozen=True)
class ComponentRuns:
    """The 8-connected groups of a 2-D mask's True cells, as runs (consecutive True cells of a row).

    Runs come in row-major order of their first cell, so their cells, one run after the other, are the mask's
    True cells in the order ``np.nonzero`` gives them. ``group`` numbers the groups 1..n in row-major order of
    their first cell (``scipy.ndimage.label``'s numbering with a 3x3 structure).
    """

    shape: tuple[int, int]
    row: np.ndarray  # (R,) int64
    col: np.ndarray  # (R,) int64: first column of each run
    length: np.ndarray  # (R,) int64
    group: np.ndarray  # (R,) int64, 1..n
    n: int

    def cells(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row, column and group of every True cell, in row-major order."""
        return np.repeat(self.row, self.length), _ranges(self.col, self.length), np.repeat(self.group, self.length)

    def line(self, r: int) -> np.ndarray:
        """The groups along row ``r`` (0 outside the mask), shape (W,)."""
        out = np.zeros(self.shape[1], np.int64)
        on = self.row == r
        out[_ranges(self.col[on], self.length[on])] = np.repeat(self.group[on], self.length[on])
        return out


def component_runs(mask: np.ndarray) -> ComponentRuns:
    """The 8-connected groups of True cells of a 2-D mask, found on its runs.

    The runs are read off the True cells' positions (``np.flatnonzero``) and joined where they touch a run of
    the next row, so a large blob costs its rows and the whole map one pass: no image of labels is made (a
    coarse map's was 27 MB).

    Parameters
    ----------
    mask : (H, W) bool array

    Returns
    -------
    ComponentRuns
    """
    mask = np.asarray(mask, dtype=bool)
    h, w = mask.shape
    pos = np.flatnonzero(mask)
    if pos.size == 0:
        empty = np.zeros(0, np.int64)
        return ComponentRuns((h, w), empty, empty, empty, empty, 0)
    row, col = np.divmod(pos, w)
    new = np.ones(pos.size, bool)
    new[1:] = (pos[1:] != pos[:-1] + 1) | (col[1:] == 0)
    first_cell = np.flatnonzero(new)
    run_row, run_col = row[first_cell], col[first_cell]
    length = np.diff(np.append(first_cell, pos.size))
    # positions in rows padded by one cell each side (row * (w + 2) + column + 1), one past each run's end
    start = run_row * (w + 2) + run_col + 1
    stop = start + length
    # a run touches the runs of the row above that end at or after its start - 1 and begin at or before its
    # stop: in that row's (sorted) runs a contiguous range, found by two binary searches
    above = (run_row - 1) * (w + 2)
    first = np.searchsorted(stop, start - (w + 2))  # first run of the row above ending at >= start - 1
    last = np.searchsorted(start, stop - (w + 2), side="right") - 1  # last one starting <= stop
    first = np.maximum(first, np.searchsorted(start, above))
    last = np.minimum(last, np.searchsorted(start, above + (w + 2)) - 1)
    n_pairs = np.where(run_row > 0, np.maximum(last - first + 1, 0), 0)
    runs_a, runs_b = _ranges(first, n_pairs), np.repeat(np.arange(start.size), n_pairs)
    roots, group = np.unique(join_groups(start.size, runs_a, runs_b), return_inverse=True)
    return ComponentRuns((h, w), run_row, run_col, length, group.reshape(-1).astype(np.int64) + 1, int(roots.size))


def label_components(mask: np.ndarray) -> tuple[np.ndarray, int]:
    """Label the 8-connected groups of True cells of a 2-D mask, numbered in row-major order of first cell.

    The labelling ``scipy.ndimage.label`` gives with a 3x3 structure, in plain numpy (importing scipy.ndimage
    cost every command that plans a visit 0.3 s), painted from :func:`component_runs`.

    Parameters
    ----------
    mask : (H, W) bool array

    Returns
    -------
    labels : (H, W) int32 array
        0 outside the mask, 1..n inside; two cells share a label when a chain of True cells, each touching
        the next at a side or a corner, joins them.
    n : int
        Number of groups.
    """
    runs = component_runs(mask)
    labels = np.zeros(runs.shape, np.int32)
    rows, cols, group = runs.cells()
    labels[rows, cols] = group
    return labels, runs.n


def _ranges(first: np.ndarray, length: np.ndarray) -> np.ndarray:
    """The integers first[i], first[i] + 1, ... (length[i] of them) for every i, one after the other."""
    return np.repeat(first, length) + (np.arange(length.sum()) - np.repeat(np.cumsum(length) - length, length))


def join_groups(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The groups of ``n`` items that the pairs ``(a[i], b[i])`` join (union-find in numpy).

    Parameters
    ----------
    n : int
        Items 0 .. n-1.
    a, b : (P,) int arrays
        Pairs of items in one group.

    Returns
    -------
    (n,) int array
        Each item's group, named by its smallest item (so groups come in the order of their first item).
    """
    parent = np.arange(n)
    a, b = np.asarray(a, dtype=np.intp), np.asarray(b, dtype=np.intp)
    while True:  # hook the larger root onto the smaller, then compress every path fully
        pa, pb = parent[a], parent[b]
        apart = pa != pb
        if not apart.any():
            return parent
        np.minimum.at(parent, np.maximum(pa[apart], pb[apart]), np.minimum(pa[apart], pb[apart]))
        while True:
            up = parent[parent]
            if np.array_equal(up, parent):
                break
            parent = up


def _merge_across_seam(first: np.ndarray, last: np.ndarray, n: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Join blobs touching both the first and last column of a full-circle map.

    ``first`` and ``last`` are the labels (1..n, 0 for none) down the map's first and last columns. Returns, per
    label, its merged label (``roots[label]``) and the column shift (0 or width) that makes the merged blob's
    columns continuous.
    """
    parent = np.arange(n + 1)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for r in range(first.size):
        for dr in (-1, 0, 1):
            rr = r + dr
            if 0 <= rr < first.size and last[r] and first[rr]:
                a, b = find(last[r]), find(first[rr])
                if a != b:
                    parent[b] = a
    shift = np.zeros(n + 1, dtype=np.int64)
    roots = np.array([find(k) for k in range(n + 1)])
    for k in range(1, n + 1):
        if roots[k] != k:  # merged: its columns (near column 0) continue after the last column
            shift[k] = width
    return roots, shift

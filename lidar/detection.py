"""Reflector detection on a reflectance map: bright compact blobs of a target's angular size.

What is bright is judged locally (:func:`local_background`): a retro-reflector outshines the surface it is glued
to at the same range, whatever the instrument's intensity scale. A scanner's raw amplitude falls as 1/range^2 and
its receiver clips: beside a deck the close concrete reads near the ceiling while targets 40 m away read less,
and on a dB scale a target and the concrete around it differ by a fraction of the scale. One threshold over the
whole map then either merges close targets with the concrete around them or misses the far ones (issue 39: 0-1
of 6 deck targets from stations 5-7 m beside a deck). A cell is bright when it rises above the background of
the cells around it by at least half the room left to the map's top and by several times the local noise; a
plateau at the ceiling is bright only where the cells around it are not (a target, not a clipped wall).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from skimage.measure import label

from common.arrays import MAD_TO_SIGMA, median_and_sigma
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
    bg, mad = median_and_sigma(v, overwrite_input=True)  # v is the sample's own copy (boolean indexing)
    return max(bg + 3.0 * mad, bg + 0.5 * (top - bg))


#: Side of the blocks the local background is the median of, degrees (a 50 mm disc at 11 m spans 0.26 deg).
LOCAL_BLOCK_DEG = 0.25
#: The background of a cell: the median of the block medians of this many blocks square around it (1.25 deg).
LOCAL_BLOCKS = 5
#: A bright cell rises from its background at least this share of the room to the map's top ...
LOCAL_RISE = 0.5
#: ... and at least this many local robust standard deviations ...
LOCAL_NOISE_FACTOR = 8.0
#: ... and at least this much (normalised intensity).
LOCAL_MIN_CONTRAST = 0.05


def _nanmedian_last(x: np.ndarray) -> np.ndarray:
    """NaN-median along the last axis (NaN where all are NaN), by one sort (np.nanmedian's small-axis path is slow)."""
    srt = np.sort(x, axis=-1)  # NaN sort last
    n = np.count_nonzero(~np.isnan(srt), axis=-1)
    lo = np.take_along_axis(srt, np.maximum((n - 1) // 2, 0)[..., None], axis=-1)[..., 0]
    hi = np.take_along_axis(srt, np.maximum(n // 2, 0)[..., None], axis=-1)[..., 0]
    out = 0.5 * (lo + hi)
    out[n == 0] = np.nan
    return out


def _block_view(a: np.ndarray, b: int) -> np.ndarray:
    """(H/b, W/b, b*b) blocks of ``a`` padded with NaN to a multiple of ``b``."""
    h, w = a.shape
    hb, wb = -(-h // b), -(-w // b)
    pad = np.full((hb * b, wb * b), np.nan, dtype=np.float32)
    pad[:h, :w] = a
    return pad.reshape(hb, b, wb, b).transpose(0, 2, 1, 3).reshape(hb, wb, b * b)


def _neighbourhood_median(m: np.ndarray, k: int, wrap: bool) -> np.ndarray:
    """NaN-median of every ``k`` x ``k`` neighbourhood of a small grid (columns wrap when ``wrap``)."""
    h, w = m.shape
    half = k // 2
    pad = np.full((h + 2 * half, w + 2 * half), np.nan, dtype=np.float32)
    pad[half:half + h, half:half + w] = m
    if wrap and w > 2 * half:
        pad[half:half + h, :half] = m[:, w - half:]
        pad[half:half + h, half + w:] = m[:, :half]
    stack = np.stack([pad[i:i + h, j:j + w] for i in range(k) for j in range(k)], axis=-1)
    return _nanmedian_last(stack)


def local_background(img: np.ndarray, step_deg: float, *, full_circle: bool = False,
                     block_deg: float = LOCAL_BLOCK_DEG, blocks: int = LOCAL_BLOCKS) -> tuple[np.ndarray, np.ndarray]:
    """The background intensity around every cell of a map and its robust noise.

    The map is cut into blocks of about ``block_deg`` (at least 2 cells); each block's median and median
    absolute deviation are taken; a cell's background is the median of the block medians of the ``blocks`` x
    ``blocks`` blocks around its own, its noise the median of their deviations (times 1.4826). A target covers
    a small part of that neighbourhood, so it does not raise its own background.

    Parameters
    ----------
    img : (H, W) array
        Cell intensities, NaN where empty.
    step_deg : float
        The map's cell size, degrees.
    full_circle : bool, keyword-only
        The columns wrap (a full-circle scan). Default False.
    block_deg : float, keyword-only
        Default :data:`LOCAL_BLOCK_DEG`.
    blocks : int, keyword-only
        Default :data:`LOCAL_BLOCKS`.

    Returns
    -------
    background, sigma : (H, W) float32 arrays
        NaN where the neighbourhood holds no return.
    """
    bg, sig, b = _local_blocks(img, step_deg, full_circle=full_circle, block_deg=block_deg, blocks=blocks)
    shape = np.shape(img)
    return _upsample(bg, b, shape), _upsample(sig, b, shape)


def _upsample(x: np.ndarray, b: int, shape: tuple[int, ...]) -> np.ndarray:
    """A block grid's values repeated over its blocks' cells, cut to the map's ``shape``."""
    return np.repeat(np.repeat(x, b, axis=0), b, axis=1)[:shape[0], :shape[1]]


def _local_blocks(img: np.ndarray, step_deg: float, *, full_circle: bool = False, block_deg: float = LOCAL_BLOCK_DEG,
                  blocks: int = LOCAL_BLOCKS) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`local_background` on the block grid: (background, sigma, block side in cells)."""
    a = np.asarray(img, dtype=np.float32)
    w = a.shape[1]
    b = max(2, int(round(block_deg / step_deg)))
    view = _block_view(a, b)
    med = _nanmedian_last(view)
    mad = _nanmedian_last(np.abs(view - med[:, :, None]))
    wrap = full_circle and w % b == 0
    bg = _neighbourhood_median(med, blocks, wrap)
    sig = _neighbourhood_median(mad, blocks, wrap) * np.float32(MAD_TO_SIGMA)
    return bg, sig, b


def bright_cells(img: np.ndarray, step_deg: float, *, full_circle: bool = False,
                 top: float | None = None) -> np.ndarray:
    """(H, W) bool: the cells that stand out of their local background (see the module text).

    A cell is bright when ``value >= background + max(LOCAL_RISE * (top - background), LOCAL_NOISE_FACTOR *
    sigma, LOCAL_MIN_CONTRAST)`` with the background and sigma of :func:`local_background` and ``top`` the map's
    brightest value (by default).
    """
    return _bright_and_floor(img, step_deg, full_circle=full_circle, top=top)[0]


def _bright_and_floor(img: np.ndarray, step_deg: float, *, full_circle: bool = False,
                      top: float | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`bright_cells` with its floor: (mask, floor blocks, block side ``b`` in cells).

    The floor, on the block grid, is the level a bright cell's weight is counted from (just below its bar).
    """
    a = np.asarray(img)
    if top is None:
        top = float(np.fmax.reduce(a, axis=None)) if a.size else np.nan
    bg, sig, b = _local_blocks(a, step_deg, full_circle=full_circle)  # constant over each block: work on blocks
    need = np.maximum(np.maximum(LOCAL_RISE * (np.float32(top) - bg), LOCAL_NOISE_FACTOR * sig),
                      np.float32(LOCAL_MIN_CONTRAST))
    bar = _upsample(bg + need, b, a.shape)
    with np.errstate(invalid="ignore"):
        # NaN (empty cells, empty neighbourhoods) compares False
        return a >= bar, bg + 0.9 * need, b


def detect_reflectors(rmap: ReflectanceMap, *, target_diameter_m: float = 0.05, threshold: float | None = None,
                      footprint_mrad: float = 0.3, max_size_factor: float = 1.6) -> DetectionResult:
    """Find reflector candidates in a reflectance map.

    Parameters
    ----------
    rmap : ReflectanceMap
    target_diameter_m : float, keyword-only
        Diameter of the campaign's targets. Default 0.05 m.
    threshold : float, optional, keyword-only
        Normalised intensity threshold over the whole map. Default none: a cell is bright when it stands out
        of its own neighbourhood (:func:`bright_cells`); the result's ``threshold`` is then
        :func:`auto_threshold`'s, for the record.
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
    if threshold is None:
        mask, floor, block = _bright_and_floor(rmap.max_intensity, rmap.step_deg, full_circle=rmap.full_circle)
        bright = mask.T
    else:
        bright, floor, block = img >= thr, None, 1
    labels, n = label(bright, connectivity=2, return_num=True)  # NaN (empty cells) compares False
    if n == 0:
        return DetectionResult((), (), thr, rmap.step_deg)
    w = labels.shape[0]  # (columns, rows)
    cols, rows = np.nonzero(labels)  # the bright cells only, in the transposed view's row-major order
    lab = labels[cols, rows]
    roots = np.arange(n + 1)
    if rmap.full_circle:
        roots, col_shift = _merge_across_seam(labels[0], labels[w - 1], n, w)
        cols = cols + col_shift[lab]  # seam-merged blobs continue past the last column
        lab = roots[lab]
    vals = img[cols % w, rows]
    weight = vals - (thr * 0.9 if floor is None else floor[rows // block, (cols % w) // block])
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
        small = size[k] <= allowed
        if small and floor is not None:  # a compact piece of a larger bright area (a clipped wall's corner)?
            small = not _part_of_larger(img, labels, roots, k, (int(col_lo[k]), int(col_hi[k])),
                                        (int(row_lo[k]), int(row_hi[k])), rmap.full_circle)
        (kept if small else rejected).append(det)
    kept.sort(key=lambda d: -d.score)
    return DetectionResult(tuple(kept), tuple(rejected), thr, rmap.step_deg)


#: A blob whose ring of cells around it is this bright (as bright as its dimmest cell) in this share or more is a
#: piece of a larger bright area, not a target: a target is surrounded by its background.
RING_SHARE = 0.25


def _part_of_larger(img: np.ndarray, labels: np.ndarray, roots: np.ndarray, k: int, col_span: tuple[int, int],
                    row_span: tuple[int, int], full_circle: bool, ring: int = 2) -> bool:
    """Whether blob ``k`` (of the transposed view ``img``) continues into cells as bright as itself around it.

    Local contrast cuts a compact piece out of a large clipped area where the background changes (its corner
    beside darker surfaces): the cells within ``ring`` cells around such a piece are as bright as its dimmest
    cell, while around a target they are its background.
    """
    w, h = labels.shape
    cc = np.arange(col_span[0] - ring, col_span[1] + ring + 1)
    cc = np.mod(cc, w) if full_circle else cc[(cc >= 0) & (cc < w)]
    rr = np.arange(max(row_span[0] - ring, 0), min(row_span[1] + ring + 1, h))
    lab = roots[labels[np.ix_(cc, rr)]]
    vals = img[np.ix_(cc, rr)]
    blob = lab == k
    grown = blob.copy()
    for dc in range(-ring, ring + 1):  # dilation by a (2 ring + 1)^2 square
        for dr in range(-ring, ring + 1):
            src = blob[max(-dc, 0):blob.shape[0] - max(dc, 0), max(-dr, 0):blob.shape[1] - max(dr, 0)]
            grown[max(dc, 0):blob.shape[0] - max(-dc, 0), max(dr, 0):blob.shape[1] - max(-dr, 0)] |= src
    around = grown & ~blob & np.isfinite(vals)
    n_around = int(np.count_nonzero(around))
    if n_around == 0:
        return False
    level = float(np.min(vals[blob]))
    return bool(np.count_nonzero(vals[around] >= level) >= RING_SHARE * n_around)


def _merge_across_seam(first: np.ndarray, last: np.ndarray, n: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Join blobs touching both the first and last column of a full-circle map.

    ``first`` and ``last`` are the labels (1..n, 0 for none) down the map's first and last columns. Returns, per
    label, its merged label (``roots[label]``: the largest label of the blobs joined, one that reaches the last
    column) and the column shift (0 or width) that makes the merged blob's columns continuous (the joined blobs
    of the first column continue after the last one).
    """
    pairs = [(int(last[r]), int(first[rr])) for r in range(first.size) for rr in (r - 1, r, r + 1)
             if 0 <= rr < first.size and last[r] and first[rr]]
    roots = np.arange(n + 1)
    shift = np.zeros(n + 1, dtype=np.int64)
    if not pairs:
        return roots, shift
    a, b = np.array(pairs).T
    _, group = connected_components(coo_matrix((np.ones(a.size), (a, b)), shape=(n + 1, n + 1)), directed=False)
    top = np.zeros(group.max() + 1, np.int64)
    np.maximum.at(top, group, np.arange(n + 1))
    roots = top[group]
    on_first = np.zeros(n + 1, bool)
    on_first[first] = True
    shift[(roots != np.arange(n + 1)) & on_first] = width
    return roots, shift

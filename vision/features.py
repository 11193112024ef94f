"""Feature detection in camera images: circle centres of the main target, checkerboard corners.

Images are 2-D arrays indexed (row, col); returned points are (u, v) = (col, row) in pixels with
integer coordinates at pixel centres (OpenCV's convention).
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations
from typing import Any

import cv2
import numpy as np

from common.errors import InputError, ProcessingError


def _as_gray_u8(image: np.ndarray, what: str) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = cv2.cvtColor(img[..., :3].astype(np.uint8), cv2.COLOR_BGR2GRAY)
    if img.ndim != 2 or img.size == 0:
        raise InputError(f"{what}: expected a grey or colour image, got an array of shape {img.shape}")
    if img.dtype != np.uint8:
        f = img.astype(np.float64)
        if not np.all(np.isfinite(f)):
            raise InputError(f"{what}: the image holds NaN or infinite values")
        lo, hi = f.min(), f.max()
        img = np.zeros(f.shape, np.uint8) if hi <= lo else np.round((f - lo) / (hi - lo) * 255).astype(np.uint8)
    return img


@dataclass(frozen=True)
class CircleDetection:
    """Bright blobs found in a main-camera image.

    centres_px : (n, 2) sub-pixel centres (u, v); ``radii_px`` (n,) equivalent radii;
    ``circularity`` (n,) 4*pi*area/perimeter^2 (1 for a perfect disc).
    """

    centres_px: np.ndarray
    radii_px: np.ndarray
    circularity: np.ndarray


def detect_circles(image: np.ndarray, *, min_radius_px: float = 3.0, max_radius_px: float = 400.0,
                   min_circularity: float = 0.6) -> CircleDetection:
    """Find bright, round blobs and their sub-pixel centres.

    The centre is the background-subtracted grey-level centroid over the blob grown by two
    pixels, so anti-aliased rims count with their partial coverage (accuracy of a few
    hundredths of a pixel on clean images).
    """
    img = _as_gray_u8(image, "main-camera image")
    thr, binary = cv2.threshold(img, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(binary, connectivity=8)
    centres, radii, circ = [], [], []
    f = img.astype(np.float64)
    for k in range(1, n):
        x, y, w, h, area = stats[k]
        r_eq = np.sqrt(area / np.pi)
        if not (min_radius_px <= r_eq <= max_radius_px):
            continue
        mask = (labels[y:y + h, x:x + w] == k).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        perim = max(cv2.arcLength(contours[0], True), 1e-9)
        c = 4 * np.pi * area / perim ** 2
        if c < min_circularity:
            continue
        pad = 3
        r0, r1 = max(0, y - pad), min(img.shape[0], y + h + pad)
        c0, c1 = max(0, x - pad), min(img.shape[1], x + w + pad)
        win = f[r0:r1, c0:c1]
        grown = cv2.dilate((labels[r0:r1, c0:c1] == k).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        ring = cv2.dilate(grown.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~grown
        background = np.median(win[ring]) if ring.any() else float(thr) / 2
        wgt = np.where(grown, np.clip(win - background, 0, None), 0.0)
        s = wgt.sum()
        if s <= 0:
            continue
        rr, cc = np.mgrid[r0:r1, c0:c1]
        centres.append(((wgt * cc).sum() / s, (wgt * rr).sum() / s))
        radii.append(r_eq)
        circ.append(min(c, 1.0))
    return CircleDetection(np.array(centres, float).reshape(-1, 2), np.array(radii, float), np.array(circ, float))


def match_pattern(centres_px: np.ndarray, pattern_m: np.ndarray, *, max_tilt_rad: float = np.pi / 4) -> np.ndarray:
    """Order detected centres like the known pattern; returns (N, 2) points, pattern order.

    Every assignment of N detections (N <= 7) is tried; the one with the smallest affine
    residual wins among those that keep the target upright (pattern x to the image's right
    and pattern y up, within ``max_tilt_rad``), which resolves the pattern's symmetries.
    """
    pattern = np.asarray(pattern_m, float)
    pts = np.asarray(centres_px, float)
    N = len(pattern)
    if len(pts) < N:
        raise ProcessingError(f"the main target shows {len(pts)} circles, {N} expected; check the camera's view "
                              "and focus")
    if N > 7:
        raise InputError("pattern matching supports targets with at most 7 features")
    if len(pts) > N:  # keep the N blobs nearest to their common centre (stray reflections are outliers)
        med = np.median(pts, axis=0)
        pts = pts[np.argsort(np.linalg.norm(pts - med, axis=1))[:N]]
    A = np.column_stack([pattern, np.ones(N)])
    pinv = np.linalg.pinv(A)
    best, best_res = None, np.inf
    for perm in permutations(range(N)):
        P = pts[list(perm)]
        coef = pinv @ P  # (3, 2): image = A @ coef
        res = float(np.linalg.norm(A @ coef - P))
        if res >= best_res:
            continue
        ang_x = np.arctan2(coef[0, 1], coef[0, 0])  # pattern +x from the image's +u
        ang_y = np.arctan2(coef[1, 0], -coef[1, 1])  # pattern +y from the image's up (-v)
        if abs(ang_x) <= max_tilt_rad and abs(ang_y) <= max_tilt_rad:
            best, best_res = P, res
    if best is None:
        raise ProcessingError("the circles found do not form the main target upright in the image")
    return best


def detect_main_target(image: np.ndarray, pattern_m: np.ndarray, **kw: Any) -> np.ndarray:
    """Circle centres of the main target in pattern order, (N, 2) pixels."""
    return match_pattern(detect_circles(image, **kw).centres_px, pattern_m)


def detect_checkerboard(image: np.ndarray, inner_corners: tuple[int, int], *, refine: bool = True
                        ) -> np.ndarray | None:
    """Inner corners of a checkerboard, (cols*rows, 2) row by row from the top-left, or None.

    Uses OpenCV's classic detector refined by ``cornerSubPix`` (about 0.03 px on a sharp
    8-bit image) and falls back to the sector-based detector. The order is made canonical: the first corner is the top-left one,
    so a board seen upright gives the same order in every frame.
    """
    img = _as_gray_u8(image, "sub-camera image")
    size = tuple(int(v) for v in inner_corners)
    ok, corners = cv2.findChessboardCorners(img, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                            + cv2.CALIB_CB_NORMALIZE_IMAGE)
    if ok and refine:
        # Search window: a quarter of the square's size in the image (at most 11 px half-width).
        grid = corners.reshape(size[1], size[0], 2)
        spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=-1)))
        half = int(np.clip(spacing / 4, 2, 11))
        corners = cv2.cornerSubPix(img, corners, (half, half), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-5))
    if not ok:  # the sector-based detector copes with blur and uneven light, at ~50x the time
        ok, corners = cv2.findChessboardCornersSB(img, size, flags=cv2.CALIB_CB_ACCURACY
                                                  + cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            return None
    pts = corners.reshape(-1, 2).astype(np.float64)
    nc, nr = size
    grid = pts.reshape(nr, nc, 2)
    if grid[0, 0, 0] > grid[0, -1, 0]:  # columns run right-to-left
        grid = grid[:, ::-1]
    if grid[0, 0, 1] > grid[-1, 0, 1]:  # rows run bottom-to-top
        grid = grid[::-1]
    return grid.reshape(-1, 2)

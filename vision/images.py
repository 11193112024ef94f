"""Image sequences of the two cameras on disk: listing, reading and feature detection per frame."""
from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from common.errors import InputError, ProcessingError
from common.progress import ProgressCallback, report
from vision.features import detect_checkerboard, detect_main_target

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm")


def list_images(folder: str | os.PathLike) -> list[Path]:
    """The images of a folder in name order (frame order)."""
    d = Path(folder)
    if not d.is_dir():
        raise InputError(f"{d}: not a folder of images")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise InputError(f"{d}: no images ({', '.join(IMAGE_SUFFIXES)})")
    return files


def read_gray(path: Path) -> np.ndarray:
    """An image file as a 2-D grayscale array indexed (row, col); a clear error when it cannot be read."""
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise InputError(f"{path}: not a readable image (corrupt, truncated or not an image format)")
    return img


def paired(main: Sequence[Path], sub: Sequence[Path]) -> None:
    """Check that the main and sub-camera image lists pair one to one (same count)."""
    if len(main) != len(sub):
        raise InputError(f"the main camera has {len(main)} images and the sub-camera {len(sub)}; each frame needs "
                         "one image of each, in the same name order")


def detect_sequence(main: Sequence[Path], sub: Sequence[Path], *, pattern_m: np.ndarray,
                    inner_corners: tuple[int, int], progress: ProgressCallback | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Main-target features (n, N, 2) and sub-target corners (n, M, 2) of every frame; NaN where not found."""
    paired(main, sub)
    n, N, M = len(main), len(pattern_m), inner_corners[0] * inner_corners[1]
    uv = np.full((n, N, 2), np.nan)
    corners = np.full((n, M, 2), np.nan)
    for k, (pm, ps) in enumerate(zip(main, sub, strict=False)):
        try:
            uv[k] = detect_main_target(read_gray(pm), pattern_m)
        except ProcessingError:
            pass  # the frame is flagged by the measurement
        c = detect_checkerboard(read_gray(ps), inner_corners)
        if c is not None:
            corners[k] = c
        report(progress, (k + 1) / n, f"frame {k + 1} of {n}")
    return uv, corners


def detect_boards(paths: Sequence[Path], inner_corners: tuple[int, int]) -> tuple[list[np.ndarray], tuple[int, int]]:
    """Corners of every image where the whole board is found (for Zhang's calibration).

    Also the image size (width, height) they share.
    """
    out, size = [], None
    for p in paths:
        img = read_gray(p)
        if size is None:
            size = img.shape[::-1]
        elif img.shape[::-1] != size:
            raise InputError(f"{p}: {img.shape[1]}x{img.shape[0]} pixels, the other views are {size[0]}x{size[1]}; "
                             "Zhang's calibration needs one camera at one resolution")
        c = detect_checkerboard(img, inner_corners)
        if c is not None:
            out.append(c)
    if size is None:
        raise InputError("no board images were given; calibrate the sub-camera from views of the checkerboard")
    return out, (int(size[0]), int(size[1]))

"""Checks made once at the public boundary of a computation."""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, DTypeLike

from common.errors import InputError


def require_points(xyz: ArrayLike, what: str, *, min_points: int = 1, finite: bool = True,
                   dtype: DTypeLike | None = np.float64) -> np.ndarray:
    """``xyz`` as an (N, 3) array of at least ``min_points`` rows (finite unless ``finite=False``).

    Raises
    ------
    InputError
        Naming ``what``, the shape received and what was expected.

    Examples
    --------
    >>> require_points([[0, 0, 1], [1, 2, 3]], "targets").shape
    (2, 3)
    >>> require_points([[0, 0]], "targets")
    Traceback (most recent call last):
    ...
    common.errors.InputError: targets: needs an (N, 3) array of points, got shape (1, 2)
    """
    a = np.asarray(xyz, dtype=dtype)
    if a.ndim != 2 or a.shape[1] != 3 or len(a) < min_points:
        at_least = f" of at least {min_points} points" if min_points > 1 else " of points"
        raise InputError(f"{what}: needs an (N, 3) array{at_least}, got shape {a.shape}")
    if finite and not np.all(np.isfinite(a)):
        raise InputError(f"{what}: coordinates hold NaN or infinite values")
    return a

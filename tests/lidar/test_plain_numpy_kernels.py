"""The plain-numpy kernels that keep scipy out of planning a visit give scipy's answers (issue 27)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from scipy.optimize import linear_sum_assignment

from lidar.detection import label_components
from lidar.identification import _assign

EIGHT = np.ones((3, 3), dtype=bool)


@pytest.mark.parametrize("shape, density", [((40, 60), 0.3), ((40, 60), 0.59), ((200, 120), 0.05), ((1, 30), 0.5),
                                            ((30, 1), 0.5), ((64, 64), 0.8)])
def test_labels_are_ndimage_labels(shape, density):
    rng = np.random.default_rng(len(shape) * 100 + int(density * 100))
    for _ in range(10):
        mask = rng.random(shape) < density
        for m in (mask, mask.T):  # a transposed view too: the map is labelled column-major
            ours, n = label_components(m)
            theirs, n_theirs = ndimage.label(m, structure=EIGHT)
            assert n == n_theirs and np.array_equal(ours, theirs)


def test_labels_of_blobs_joined_only_at_a_corner_a_snake_and_an_empty_map():
    corner = np.zeros((4, 4), bool)
    corner[0, 0] = corner[1, 1] = corner[2, 3] = corner[3, 2] = True
    labels, n = label_components(corner)
    assert n == 2 and labels[0, 0] == labels[1, 1] == 1 and labels[2, 3] == labels[3, 2] == 2
    snake = np.zeros((41, 41), bool)  # one group winding through every row: the joins must chain
    snake[::2] = True
    snake[1::4, -1] = True
    snake[3::4, 0] = True
    labels, n = label_components(snake)
    assert n == 1 and (labels[snake] == 1).all() and (labels[~snake] == 0).all()
    labels, n = label_components(np.zeros((5, 7), bool))
    assert n == 0 and labels.shape == (5, 7) and labels.dtype == np.int32


def _scipy_pairs(d, tol):
    r, c = linear_sum_assignment(np.where(d <= tol, d, 1e6))
    return [(int(a), int(b)) for a, b in zip(r, c, strict=False) if d[a, b] <= tol]


def test_assignment_is_the_optimal_one():
    rng = np.random.default_rng(4)
    for _ in range(400):
        n, m = rng.integers(1, 10, 2)
        pred, det = rng.uniform(0, 2, (n, 3)), rng.uniform(0, 2, (m, 3))
        tol = float(rng.uniform(0.05, 1.2))
        d = np.linalg.norm(pred[:, None] - det[None], axis=2)
        ours = _assign(pred, det, tol)
        theirs = _scipy_pairs(d, tol)
        assert len(ours) == len(theirs)  # as many pairs ...
        assert sum(p[2] for p in ours) == pytest.approx(sum(d[a, b] for a, b in theirs), abs=1e-12)  # ... as short
        assert [p[:2] for p in ours] == sorted(theirs)  # the same pairs (no ties among random distances)
        assert all(p[2] <= tol for p in ours)

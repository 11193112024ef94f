"""The plain-numpy assignment of layout targets to detections gives scipy's answers (issue 27)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from lidar.identification import _assign


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

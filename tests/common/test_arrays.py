import numpy as np

from common.arrays import unique_sorted


def test_unique_sorted_is_numpys_unique():
    rng = np.random.default_rng(0)
    for values in (rng.integers(0, 50, 1000), rng.integers(0, 2**62, 5000).astype(np.uint64), rng.random(300),
                   np.array([3.0, -0.0, 0.0, np.inf, -np.inf, 3.0]), np.array([7]), np.array([], np.int64)):
        got = unique_sorted(values)
        assert got.dtype == values.dtype
        np.testing.assert_array_equal(got, np.unique(values))

import numpy as np
import pytest

from common.arrays import median, unique_sorted


def test_unique_sorted_is_numpys_unique():
    rng = np.random.default_rng(0)
    for values in (rng.integers(0, 50, 1000), rng.integers(0, 2**62, 5000).astype(np.uint64), rng.random(300),
                   np.array([3.0, -0.0, 0.0, np.inf, -np.inf, 3.0]), np.array([7]), np.array([], np.int64)):
        got = unique_sorted(values)
        assert got.dtype == values.dtype
        np.testing.assert_array_equal(got, np.unique(values))


@pytest.mark.parametrize("n", [1, 2, 7, 1000, 1001])
@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int64])
def test_median_is_numpys_median(n, dtype):
    v = (np.random.default_rng(n).normal(size=n) * 100).astype(dtype)
    assert median(v) == float(np.median(v))
    assert median(np.sort(v)[::-1]) == float(np.median(v))  # not contiguous, any order


def test_median_of_an_empty_array_or_one_with_a_nan_is_nan_as_numpys():
    assert np.isnan(median(np.array([]))) and np.isnan(median(np.array([1.0, np.nan, 3.0])))
    assert np.isnan(median(np.array([np.nan, 2.0]))) and np.isnan(median(np.array([np.nan])))
    assert np.isnan(np.median(np.array([1.0, np.nan, 3.0])))  # the behaviour copied


def test_median_overwriting_its_input_partitions_it_in_place():
    v = np.random.default_rng(3).normal(size=1001)
    want, kept = float(np.median(v)), v.copy()
    assert median(v, overwrite_input=True) == want
    assert not np.array_equal(v, kept) and np.array_equal(np.sort(v), np.sort(kept))

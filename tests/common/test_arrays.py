import numpy as np

from common.arrays import unique_sorted


def test_unique_sorted_is_numpys_unique():
    rng = np.random.default_rng(0)
    for values in (rng.integers(0, 50, 1000), rng.integers(0, 2**62, 5000).astype(np.uint64), rng.random(300),
                   np.array([3.0, -0.0, 0.0, np.inf, -np.inf, 3.0]), np.array([7]), np.array([], np.int64)):
        got = unique_sorted(values)
        assert got.dtype == values.dtype
        np.testing.assert_array_equal(got, np.unique(values))


def test_median_and_sigma_is_the_median_and_1_4826_times_the_median_absolute_deviation():
    from scipy.stats import median_abs_deviation

    from common.arrays import median_and_sigma

    v = np.random.default_rng(5).normal(3.0, 2.0, 1001)
    med, sigma = median_and_sigma(v)
    assert med == float(np.median(v)) and sigma == 1.4826 * float(median_abs_deviation(v))
    w = v.copy()
    assert median_and_sigma(w, overwrite_input=True) == (med, sigma)
    with_nan = np.append(v, np.nan).astype(np.float32).reshape(2, -1)
    m32, s32 = median_and_sigma(with_nan, skip_nan=True)
    assert m32 == float(np.nanmedian(with_nan)) and s32 == 1.4826 * float(np.nanmedian(np.abs(with_nan - m32)))
    assert all(np.isnan(median_and_sigma(with_nan)))


def test_thin_to_voxels_keeps_the_first_point_of_each_cube_in_order():
    from common.arrays import thin_to_voxels

    xyz = np.array([[0.01, 0.0, 0.0], [0.5, 0.5, 0.5], [0.02, 0.03, 0.01], [-0.01, 0.0, 0.0], [0.6, 0.4, 0.45]])
    np.testing.assert_array_equal(thin_to_voxels(xyz, 0.1), xyz[[0, 1, 3, 4]])
    np.testing.assert_array_equal(thin_to_voxels(xyz, 1.0), xyz[[0, 3]])

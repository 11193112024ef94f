"""Cross-validation statistics against known answers."""
import numpy as np
import pytest

from common.errors import ProcessingError
from vision.crossval import cross_validate
from vision.series import CameraSeries

H = 3600 * 10 ** 9


def _camera(truth, offset, noise=0.0, n_days=30, rng=None):
    rng = rng or np.random.default_rng(0)
    t = np.arange(0, n_days * 24 * H, 60 * 10 ** 9, dtype=np.int64)
    return CameraSeries(time_ns=t, value_mm=truth(t) + offset + rng.normal(0, noise, len(t)))


def truth(t):
    return -3.0 * (t / (30 * 24 * H))


def test_exact_series_give_zero_bias_and_rmse_and_unit_correlation():
    t = np.arange(1, 29) * 24 * H
    cv = cross_validate([f"e{k}" for k in range(len(t))], t, truth(t), np.full(len(t), 0.1), _camera(truth, 7.5))
    assert cv.n_pairs == len(t)
    assert cv.offset_mm == pytest.approx(-7.5, abs=1e-9)
    assert cv.bias_mm == pytest.approx(0, abs=1e-9) and cv.rmse_mm == pytest.approx(0, abs=1e-9)
    assert cv.correlation == pytest.approx(1.0) and cv.slope == pytest.approx(1.0)


def test_known_bias_after_alignment_at_a_date_and_noise_statistics():
    rng = np.random.default_rng(5)
    t = np.arange(1, 29) * 24 * H
    lidar = truth(t) + 0.4  # LiDAR reads 0.4 mm high from the 2nd epoch on, except at the aligned one
    lidar[0] = truth(t[0])
    cv = cross_validate([str(k) for k in range(len(t))], t, lidar, np.full(len(t), 0.1),
                        _camera(truth, 2.0, noise=0.2, rng=rng), align_at_ns=int(t[0]) + H // 2)
    assert cv.alignment["method"] == "at-date" and cv.alignment["epoch"] == "0"
    assert cv.bias_mm == pytest.approx(0.4 * 27 / 28, abs=0.03)
    assert cv.rmse_mm == pytest.approx(np.sqrt((0.4 ** 2 * 27) / 28), abs=0.03)
    # the camera median of ~60 samples has sigma ~0.2 * 1.25 / sqrt(60)
    assert 0.02 < cv.pairs[3].camera_sigma_mm < 0.06 and cv.pairs[3].camera_n == 61


def test_epochs_without_camera_data_are_flagged_and_left_out():
    t = np.array([5, 10, 40]) * 24 * H  # the camera stops after 30 days
    cv = cross_validate(["a", "b", "c"], t, truth(t), np.full(3, 0.1), _camera(truth, 0.0))
    assert cv.n_pairs == 2 and cv.pairs[2].flags == ("no_camera_data",) and np.isnan(cv.pairs[2].difference_mm)
    assert np.isnan(cv.correlation)  # fewer than three pairs
    with pytest.raises(ProcessingError, match="no LiDAR epoch has camera samples"):
        cross_validate(["c"], t[2:], truth(t[2:]), np.full(1, 0.1), _camera(truth, 0.0))

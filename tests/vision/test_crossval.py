"""Cross-validation statistics against known answers."""
import numpy as np
import pytest

from common.errors import ProcessingError
from common.series import Series
from vision.crossval import cross_validate

H = 3600 * 10 ** 9


def _camera(truth, offset, noise=0.0, n_days=30, rng=None):
    rng = rng or np.random.default_rng(0)
    t = np.arange(0, n_days * 24 * H, 60 * 10 ** 9, dtype=np.int64)
    return Series(unit="mm", time_ns=t, values=truth(t) + offset + rng.normal(0, noise, len(t)))


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
    assert np.isnan(cv.correlation) and not cv.has_statistics  # two pairs: too few for statistics
    with pytest.raises(ProcessingError, match="no LiDAR epoch has camera samples"):
        cross_validate(["c"], t[2:], truth(t[2:]), np.full(1, 0.1), _camera(truth, 0.0))


def test_fewer_than_min_pairs_give_no_statistics_and_say_so():
    from vision.crossval import MIN_PAIRS

    t = np.arange(1, MIN_PAIRS) * 24 * H  # one pair short
    cv = cross_validate([str(k) for k in range(len(t))], t, truth(t) + 0.3, np.full(len(t), 0.1), _camera(truth, 1.0))
    assert cv.n_pairs == MIN_PAIRS - 1 and not cv.has_statistics
    for name in ("bias_mm", "rmse_mm", "std_mm", "max_abs_mm", "correlation", "slope", "within_2sigma"):
        assert np.isnan(getattr(cv, name)), name
    assert cv.note == f"only {MIN_PAIRS - 1} pairs: too few for statistics ({MIN_PAIRS} needed)"
    assert cv.statistics_text() == cv.note and "RMSE" not in cv.statistics_text()
    assert np.isfinite(cv.offset_mm) and cv.pairs[0].camera_n > 0  # the pairs themselves are still there
    t5 = np.arange(1, MIN_PAIRS + 1) * 24 * H
    cv5 = cross_validate([str(k) for k in range(len(t5))], t5, truth(t5), np.full(len(t5), 0.1), _camera(truth, 1.0))
    assert cv5.has_statistics and cv5.note == "" and cv5.rmse_mm < 1e-9 and "RMSE 0.000 mm" in cv5.statistics_text()


def test_a_camera_series_of_one_row_claims_no_agreement():
    """Issue 29: one row paired with one epoch and aligned on itself read 'RMSE 0.000 mm, 100 % within 2 sigma'."""
    t = np.arange(1, 10) * 24 * H
    one = Series(unit="mm", time_ns=np.array([t[4] + 60 * 10 ** 9], np.int64), values=np.array([3.0]))
    cv = cross_validate([str(k) for k in range(len(t))], t, truth(t), np.full(len(t), 0.1), one)
    assert cv.n_pairs == 1 and np.isnan(cv.rmse_mm) and np.isnan(cv.within_2sigma)
    assert "only 1 pair: too few for statistics" in cv.statistics_text()
    assert "100 %" not in cv.statistics_text() and "0.000" not in cv.statistics_text()
    from common.files import json_safe

    doc = json_safe(cv.to_json())
    assert doc["rmse_mm"] is None and doc["within_2sigma"] is None and "too few" in doc["note"]


def test_an_older_summary_of_few_pairs_loses_its_statistics_when_read_back():
    t = np.arange(1, 29) * 24 * H
    cv = cross_validate([f"e{k}" for k in range(len(t))], t, truth(t), np.full(len(t), 0.1), _camera(truth, 7.5))
    from vision.crossval import CrossValidation

    back = CrossValidation.from_json(cv.to_json())
    assert back.has_statistics and back.rmse_mm == pytest.approx(cv.rmse_mm) and back.n_pairs == cv.n_pairs
    old = {k: v for k, v in cv.to_json().items() if k != "note"}  # written before the note existed
    old.update(n_pairs=1, rmse_mm=0.0, within_2sigma=1.0)
    back = CrossValidation.from_json(old)
    assert not back.has_statistics and np.isnan(back.rmse_mm) and np.isnan(back.within_2sigma)


def test_pairing_alignment_and_statistics_are_separate_steps():
    from vision.crossval import agreement, align_camera, pair_with_camera

    cam = Series(unit="mm", time_ns=np.array([0, 60, 120, 3600, 7200], np.int64) * 10 ** 9,
                       values=np.array([1.0, 2.0, 3.0, np.nan, 5.0]))
    at = pair_with_camera(np.array([60, 3600, 7200 + 60], np.int64) * 10 ** 9, cam, window_s=90)
    assert at.count.tolist() == [3, 0, 1] and at.median_mm[0] == 2.0 and np.isnan(at.median_mm[1])
    assert at.median_mm[2] == 5.0 and at.sigma_mm[2] == 0.0  # one sample: no spread to judge
    y, c = np.array([1.0, 2.0, 3.0]), np.array([0.0, 1.0, 2.5])
    paired = np.array([True, True, True])
    offset, how = align_camera(["a", "b", "c"], np.array([0, 1, 2]), y, c, np.ones(3), paired)
    assert how["method"] == "least-squares" and offset == pytest.approx(0.8333333333)
    offset, how = align_camera(["a", "b", "c"], np.array([0, 10, 20]), y, c, np.ones(3), paired, align_at_ns=11)
    assert how["epoch"] == "b" and offset == pytest.approx(1.0)
    few = agreement(y, c, y - c - 1.0, np.ones(3), paired)
    assert few.n_pairs == 3 and np.isnan(few.rmse_mm) and "too few" in few.note
    y6, c6 = np.arange(6.0), np.arange(6.0) + 0.1
    ok = agreement(y6, c6, y6 - c6, np.full(6, 0.04), np.ones(6, bool))
    assert ok.bias_mm == pytest.approx(-0.1) and ok.rmse_mm == pytest.approx(0.1) and ok.within_2sigma == 0.0
    assert ok.correlation == pytest.approx(1.0) and ok.note == ""

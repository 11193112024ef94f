"""What an epoch was corrected for, in words and numbers (status, report, application)."""
from __future__ import annotations

import math

import pytest

from projects.results.corrections import corrections_line, epoch_corrections


def record(**kw) -> dict:
    base = {"scale_ppm": 12.34, "scale_sigma_ppm": 1.06, "scale_determined": True,
            "drift_arcsec_h": [30.0, -40.0, 5.0], "drift_sigma_arcsec_h": [3.0, 4.0, 2.0], "timed": True,
            "time_source": "points", "range_walk": ["c1"], "left_out": []}
    return {**base, **kw}


def test_no_record_says_nothing():
    assert corrections_line({}) == "" and epoch_corrections({}) is None


def test_scale_and_drift_with_their_sigmas():
    e = epoch_corrections(record())
    assert e.tilt_arcsec_h == pytest.approx(50.0)  # |(30, -40)|
    # first-order sigma of the norm: sqrt((30*3)^2 + (40*4)^2) / 50
    assert e.tilt_sigma_arcsec_h == pytest.approx(math.hypot(90, 160) / 50)
    assert e.twist_arcsec_h == 5.0 and e.twist_sigma_arcsec_h == 2.0
    line = corrections_line(record())
    assert line.startswith("scale +12.3 ± 1.1 ppm; drift: tilt 50 ± 4″/h, twist 5 ± 2″/h (times from the points)")


@pytest.mark.parametrize("kw, words", [
    ({"scale_determined": False}, "scale not determined (its prior, 0 ± 1.1 ppm, is in σ)"),
    ({"timed": False, "time_source": "plan"}, "no drift (the campaign's data do not support one)"),
    ({"timed": False, "time_source": "none"}, "drift not estimated (the epoch has no times)"),
    ({"left_out": ["R3"]}, "left out of the frame: R3"),
])
def test_what_the_data_could_not_tell_is_said(kw, words):
    assert words in corrections_line(record(**kw))


def test_the_baseline_defines_the_scale():
    assert corrections_line(record(), baseline=True).startswith("scale 0 ppm (the baseline defines it)")


def test_a_zero_drift_has_the_larger_sigma():
    e = epoch_corrections(record(drift_arcsec_h=[0.0, 0.0, 0.0]))
    assert e.tilt_arcsec_h == 0.0 and e.tilt_sigma_arcsec_h == 4.0


def test_status_words_for_the_instrument_of_a_field_model():
    import numpy as np

    from lidar.systematic.adjustment import FieldModel
    from lidar.systematic.axes import AXIS_NAMES, AxisModel
    from lidar.systematic.range_walk import RangeWalkModel
    from projects.results.corrections import instrument_line, instrument_summary

    axes = AxisModel((2,), np.array([28.04]), np.array([[56.25]]))
    s = instrument_summary(FieldModel("b", RangeWalkModel(), {}, 0.876, axes=axes))
    assert s == {"range_walk": "none", "range_walk_determined": True, "sigma0": 0.88,
                 "axis_errors": [{"axis": AXIS_NAMES[2], "arcsec": 28.0, "sigma_arcsec": 7.5}]}
    assert instrument_line(s) == f"range walk: none; axis errors: {AXIS_NAMES[2]} +28.0 ± 7.5″"
    none = instrument_summary(FieldModel("b", RangeWalkModel(), {}))
    assert instrument_line(none) == "range walk: none; axis errors: none the data support"

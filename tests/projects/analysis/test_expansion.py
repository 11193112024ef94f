"""The deck's along-span expansion coefficient per target, and a seized bearing."""
from __future__ import annotations

import numpy as np
import pytest

from projects.analysis.expansion import fit_along, temperatures_at


def test_the_coefficient_is_recovered_with_an_honest_sigma():
    rng = np.random.default_rng(2)
    ks, sigmas = [], []
    for _ in range(200):
        t = rng.uniform(-10, 30, 12)
        along = 0.45 * t + rng.normal(0, 0.05, t.size)
        f = fit_along("M5", t, along, np.full(t.size, 0.05))
        ks.append(f.mm_per_degC)
        sigmas.append(f.sigma)
    err = (np.array(ks) - 0.45) / np.array(sigmas)
    assert abs(np.mean(ks) - 0.45) < 0.001 and 0.8 < np.std(err) < 1.25


def test_a_bearing_that_stops_sliding_is_said():
    t = np.tile([0.0, 10.0, 20.0, 5.0, 15.0, 25.0], 2)
    along = np.r_[0.5 * t[:6], 0.02 * t[6:]]  # slides, then seized
    f = fit_along("M6", t, along, np.full(t.size, 0.03))
    assert f.early_late is not None and "stops sliding" in f.note
    steady = fit_along("M6", t, 0.5 * t, np.full(t.size, 0.03))
    assert steady.note == ""


@pytest.mark.parametrize("temps, why", [([1.0, 2.0], "3 needed"), ([10.0, 10.2, 10.4, 10.1], "too little")])
def test_no_coefficient_without_enough_epochs_or_temperature_range(temps, why):
    f = fit_along("M1", temps, np.zeros(len(temps)), np.full(len(temps), 0.05))
    assert f.mm_per_degC is None and why in f.note


def test_temperatures_at_the_scans():
    series = (np.array([0.0, 0.02, 1.0, 5.0]), np.array([10.0, 12.0, 20.0, 30.0]))
    got = temperatures_at(np.array([0.01, 3.0, 5.0]), series)
    assert got[0] == pytest.approx(11.0) and np.isnan(got[1]) and got[2] == 30.0

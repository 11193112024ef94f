"""The displacement model against synthetic histories with known temperature effect, steps and creep."""
import numpy as np

from projects.analysis.models import Event, creep_shape, effective_temperature, first_crossing, fit_target


def synthetic(rng, *, b=0.2, steps=((144.0, -6.5), (333.0, -2.0)), phi=1.3, d_days=20.0, noise=0.1, days=650,
              window_h=6.0):
    th = np.arange(0, days, 1 / 24)
    temp = 10 - 12 * np.cos(2 * np.pi * (th - 15) / 365.25) + 4 * np.sin(2 * np.pi * (th % 1 - 0.4)) \
        + rng.normal(0, 0.5, th.size)
    te = np.arange(3, days, 7) + rng.uniform(0.35, 0.45, np.arange(3, days, 7).size)
    teff = effective_temperature(te, th, temp, window_h, 0.0)
    d = b * (teff - np.median(teff))
    for t0, s in steps:
        h = te >= t0
        d = d + h * (s + phi * s * creep_shape(te - t0, d_days))
    return te, d + rng.normal(0, noise, te.size), (th, temp)


def test_recovers_the_thermal_coefficient_steps_and_creep_coefficients():
    rng = np.random.default_rng(3)
    t, d, temp = synthetic(rng)
    fit = fit_target(t, d, np.full(t.size, 0.1), temperature=temp,
                     events=[Event(144.0, "slab"), Event(333.0, "ballast")])
    assert abs(fit.thermal_mm_per_degC - 0.2) < 3 * fit.thermal_sigma
    assert fit.thermal_p_value < 1e-6 and fit.temperature_window_h == 6.0
    slab, ballast = sorted(fit.events, key=lambda e: e.label, reverse=True)
    assert abs(slab.step_mm + 6.5) < 3 * slab.step_sigma_mm
    developed = 1.3 * float(creep_shape(t[-1] - 144.0, 20.0))
    assert abs(slab.creep_coefficient - developed) < 3 * slab.creep_coefficient_sigma
    assert abs(slab.creep_coefficient_final - 1.3) < 3 * slab.creep_coefficient_final_sigma
    assert abs(ballast.step_mm + 2.0) < 3 * ballast.step_sigma_mm
    assert fit.corrected_mm.size == t.size and np.all(fit.corrected_sigma_mm >= 0.1)


def test_what_cannot_be_determined_says_so():
    rng = np.random.default_rng(4)
    t, d, temp = synthetic(rng, steps=((144.0, -6.5),))
    late = Event(float(t[-1]) - 3.0, "too late")
    fit = fit_target(t, d, np.full(t.size, 0.1), temperature=temp, events=[Event(144.0, "slab"), late])
    bad = [e for e in fit.events if e.label == "too late"][0]
    assert np.isnan(bad.step_mm) and "not determinable" in bad.note
    few = fit_target(t[:3], d[:3], np.full(3, 0.1))
    assert np.isnan(few.thermal_mm_per_degC) and "too few" in few.notes[0]
    far = (temp[0] + 5000.0, temp[1])  # a temperature series that does not overlap the epochs
    nofit = fit_target(t, d, np.full(t.size, 0.1), temperature=far, events=[Event(144.0, "slab")])
    assert np.isnan(nofit.thermal_mm_per_degC) and any("does not overlap" in n for n in nofit.notes)


def test_projection_finds_when_a_level_is_reached_with_a_band():
    rng = np.random.default_rng(5)
    t = np.arange(0, 400, 7.0)
    d = -0.01 * t + rng.normal(0, 0.05, t.size)  # -3.65 mm/year
    fit = fit_target(t, d, np.full(t.size, 0.05))
    assert abs(fit.trend_mm_per_year + 3.65) < 3 * fit.trend_sigma
    central, early, late = first_crossing(fit, float(t[-1]), float(t[-1]) + 3650, -10.0)
    assert early <= central <= late
    assert abs(central - 1000) < 30  # -10 mm at day 1000
    assert first_crossing(fit, float(t[-1]), float(t[-1]) + 100, -100.0) is None


def test_sigmas_are_honest_over_many_histories():
    """Share of true values within 2 sigma over 40 random histories (thermal, steps, creep)."""
    rng = np.random.default_rng(11)
    inside, total = 0, 0
    for _ in range(40):
        b, phi = rng.uniform(0.05, 0.3), rng.uniform(0.8, 2.0)
        s1, s2 = -rng.uniform(3, 8), -rng.uniform(1, 3)
        t, d, temp = synthetic(rng, b=b, steps=((144.0, s1), (333.0, s2)), phi=phi, noise=rng.uniform(0.08, 0.3))
        fit = fit_target(t, d, np.full(t.size, 0.1), temperature=temp, events=[Event(144.0, "a"), Event(333.0, "b")])
        a = [e for e in fit.events if e.label == "a"][0]
        developed = phi * float(creep_shape(t[-1] - 144.0, 20.0))
        for est, sig, truth in ((fit.thermal_mm_per_degC, fit.thermal_sigma, b), (a.step_mm, a.step_sigma_mm, s1),
                                (a.creep_coefficient, a.creep_coefficient_sigma, developed)):
            inside += abs(est - truth) <= 2 * sig
            total += 1
    assert inside / total >= 0.9


def test_the_model_pieces_design_matrix_search_average_and_predictor():
    import dataclasses
    import doctest

    import pytest

    import projects.analysis.models as m

    assert doctest.testmod(m).failed == 0
    e = Event(10.0, "load")
    terms = (m.Term("offset"), m.Term("thermal"), m.Term("step", e), m.Term("creep", e), m.Term("trend"))
    t = np.array([0.0, 10.0, 20.0])
    X = m.design_matrix(t, terms, creep_law=("exp", 10.0), temperature_deviation=np.array([1.0, -1.0, 0.5]))
    assert X[:, 0].tolist() == [1, 1, 1] and X[:, 1].tolist() == [1.0, -1.0, 0.5] and X[:, 2].tolist() == [0, 1, 1]
    assert X[:, 3] == pytest.approx([0.0, 0.0, 1 - np.exp(-1.0)]) and X[:, 4] == pytest.approx(t / m.YEAR_D)
    assert m.design_matrix(t, terms[:2], creep_law=None)[:, 1].tolist() == [0, 0, 0]  # at the reference temperature
    # the candidates are frozen records, the best one has the lowest AICc
    rng = np.random.default_rng(2)
    tt = np.arange(0.0, 300.0, 7.0)
    d = -2.0 * (tt >= 100) + rng.normal(0, 0.05, tt.size)
    specs = list(m.model_specs(tt, [None], [(Event(100.0, "x"), False)]))
    best, per_law = m.search_models(tt, d, np.full(tt.size, 400.0), specs)
    assert best is not None and best.aicc == min(c.aicc for c in per_law)
    with pytest.raises(dataclasses.FrozenInstanceError):
        best.aicc = 0.0  # type: ignore[misc]
    step = best.estimate(m.Term("step", Event(100.0, "x")))
    assert step is not None and abs(step[0] + 2.0) < 0.1
    # Akaike averaging adds the spread between the models to the variance
    mean, sigma = m.akaike_average(np.array([0.5, 0.5]), [(1.0, 0.01), (3.0, 0.01)])
    assert mean == pytest.approx(2.0) and sigma == pytest.approx(np.sqrt(1.01))
    assert np.isnan(m.akaike_average(np.array([1.0]), [None])[0])
    fit = fit_target(tt, d, np.full(tt.size, 0.05), events=[Event(100.0, "x")])
    v, s = fit.predict([50.0, 150.0])
    assert v[1] - v[0] == pytest.approx(-2.0, abs=0.1) and np.all(s > 0)
    assert fit.measured_mm.tolist() == d.tolist()


def test_a_negative_creep_coefficient_gets_a_note():
    """Issue 25.9: a recovery after the step, or a coefficient the epochs cannot tell from zero, says so."""
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 400.0, 7.0)
    recovery = (t >= 100) * (-3.0 + 1.5 * (1 - np.exp(-(t - 100) / 40.0)))  # half the step comes back
    fit = fit_target(t, recovery + rng.normal(0, 0.05, t.size), np.full(t.size, 0.05), events=[Event(100.0, "load")])
    e = fit.events[0]
    assert e.creep_coefficient < -2 * e.creep_coefficient_sigma
    assert "negative creep coefficient" in e.note and "recovery" in e.note
    flat = (t >= 100) * -3.0 + rng.normal(0, 0.1, t.size)  # no creep at all
    e = fit_target(t, flat, np.full(t.size, 0.1), events=[Event(100.0, "load")]).events[0]
    assert abs(e.creep_coefficient) <= 2 * e.creep_coefficient_sigma and "not determinable" in e.note
    creep = (t >= 100) * (-3.0 * (1 + 1.2 * (1 - np.exp(-(t - 100) / 40.0)))) + rng.normal(0, 0.05, t.size)
    e = fit_target(t, creep, np.full(t.size, 0.05), events=[Event(100.0, "load")]).events[0]
    assert e.creep_coefficient > 2 * e.creep_coefficient_sigma and e.note == ""

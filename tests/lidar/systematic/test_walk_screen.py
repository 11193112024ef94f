"""Every range-walk law screened on the linearised adjustment: the same fits as the full one, every threshold."""
from __future__ import annotations

import numpy as np
import pytest

from lidar.simulate.effects import InverseSquareWalk, StrengthStepWalk
from lidar.systematic import adjustment as adj
from lidar.systematic.budget import corrected_displacements
from lidar.systematic.range_walk import PLAUSIBLE_BIC, design, family_spread2, step_name
from lidar.systematic.walk_screen import BiasInformation, bias_information, screen_laws, threshold_penalty
from tests.lidar.systematic.test_field_model import campaign

#: A step of 1.3 mm at strength 0.5: on this campaign the step the old sparse search found was at 0.15 and a
#: smooth law was chosen, 25 BIC units worse than a step at 0.49, leaving deck errors of 5 sigma unflagged.
STEP = StrengthStepWalk(0.0015, 0.0002, 0.5)


def _general(seed: int, walk=STEP):
    g, ids, groups, visits, cents, truths = campaign(walk=walk, ppm=30.0, seed=seed)
    general = adj.AdjustmentProblem(visits, groups, ("1", "sat_strength"))
    adj._adjust(general)
    return general, visits, groups


def _exact(visits, groups, general, basis):
    p = adj.AdjustmentProblem(visits, groups, basis, start=general)
    for _ in range(3):
        sol, _ = adj._solve_once(p)
    return sol.chi2, p.theta, np.array([v.kappa_ppm for v in p.visits])


@pytest.mark.parametrize("basis", [(), ("1",), ("cos",), ("1", "soft_r2"), ("cos", "inv_r2"),
                                   ("1", step_name("s", 0.49)), ("1", step_name("c", 0.3))])
def test_the_linearised_fit_is_the_full_one(basis):
    general, visits, groups = _general(3)
    info = bias_information(adj.AdjustmentProblem(visits, groups, (), start=general))
    d = design(basis, info.range_m, info.cos_incidence)
    chi2, theta = info.chi2(d)
    chi2_full, theta_full, kappas_full = _exact(visits, groups, general, basis)
    # the full fit's two Gauss-Newton steps move the poses a little further: within 1e-5 of chi2, 1e-4 mm, 1e-3 ppm
    assert chi2 == pytest.approx(chi2_full, rel=1e-5)
    np.testing.assert_allclose(theta, theta_full, atol=1e-4)
    np.testing.assert_allclose(info.scales_ppm(d, theta), kappas_full, atol=1e-3)


def test_every_threshold_is_screened_as_if_fitted_alone():
    general, visits, groups = _general(5)
    info = bias_information(adj.AdjustmentProblem(visits, groups, (), start=general))
    laws = screen_laws(info, 180)
    steps = [law for law in laws if len(law.basis) == 2 and law.basis[1].startswith("step_")]
    s = info.range_m.size
    for proxy in ("s", "c", "q"):  # one step at every midpoint that leaves 3 sightings on each side
        mine = [law for law in steps if law.basis[1].startswith(f"step_{proxy}@")]
        assert 0.5 * s < len(mine) <= s - 5
    per_proxy = {p: sum(1 for law in steps if law.basis[1].startswith(f"step_{p}@")) for p in ("s", "c", "q")}
    for law in steps[::17]:  # the suffix sums give what the law's own design gives; the threshold is counted
        chi2, theta = info.chi2(design(law.basis, info.range_m, info.cos_incidence))
        assert law.bic == pytest.approx(chi2 + 2 * np.log(180) + 2 * np.log(per_proxy[law.basis[1][5]]),
                                        rel=1e-9, abs=1e-9)
        np.testing.assert_allclose(law.theta_mm, theta, atol=1e-9)
    with pytest.raises(ValueError):
        bias_information(general)  # needs the problem without a walk


def test_the_best_step_is_found_and_the_displacements_stay_within_their_sigma():
    g, ids, groups, visits, cents, truths = campaign(walk=STEP, ppm=30.0, seed=3)
    model = adj.fit_field_model(visits, groups)
    (name,) = model.range_walk.basis[1:]
    assert name.startswith("step_s@") and 0.47 < float(name.split("@")[1]) < 0.52
    for k in range(1, len(cents)):
        res = corrected_displacements(cents[0], cents[k], groups, model=model, baseline_label="0", epoch_label=str(k))
        for d in res.displacements:
            j = ids.index(d.reflector)
            assert abs(d.displacement_m - (truths[k][j, 2] - truths[0][j, 2])) < 3.0 * d.sigma_m
            assert abs(d.along_m - (truths[k][j, 0] - truths[0][j, 0])) < 3.0 * d.along_sigma_m


def test_a_smooth_walk_is_not_taken_for_a_step():
    g, ids, groups, visits, cents, truths = campaign(walk=InverseSquareWalk(0.003, 15.0), ppm=30.0, seed=2)
    model = adj.fit_field_model(visits, groups)
    assert not any(b.startswith("step_") for b in model.range_walk.basis)


def test_the_families_spread_is_the_largest_departure_among_the_plausible():
    departures = np.array([[0.0, 0.0], [0.3, -0.1], [-0.5, 0.2], [2.0, 3.0]])
    weights = np.array([1.0, 0.5, np.exp(-0.5 * (PLAUSIBLE_BIC - 0.01)), np.exp(-0.5 * (PLAUSIBLE_BIC + 0.01))])
    np.testing.assert_allclose(family_spread2(departures, weights), [0.25, 0.04])  # the last is not plausible
    np.testing.assert_allclose(family_spread2(departures[:1], weights[:1]), [0.0, 0.0])
    assert family_spread2(np.zeros((0, 3)), np.zeros(0)).shape == (3,)


def _independent_biases(rng: np.random.Generator, step_mm: float, n: int = 150) -> BiasInformation:
    """Every sighting's range bias measured on its own to 0.1 mm (``M = 100 I``), a step at strength 0.5 or none."""
    r = rng.uniform(8.0, 40.0, n)
    c = rng.uniform(0.3, 1.0, n)
    truth = step_mm * (design((step_name("s", 0.5),), r, c)[:, 0])
    info = 100.0 * np.eye(n)
    z = rng.normal(0.0, 1.0, n)  # whitened noise
    gradient = info @ truth + 10.0 * z  # g = J^T e: the bias per mm, sigma 0.1 mm a sighting
    chi2_without = float(np.sum((10.0 * truth + z) ** 2))
    return BiasInformation(info, gradient, chi2_without, r, c, np.zeros(1), np.zeros((1, n)),
                           (np.zeros((0, 0)), np.zeros((0, n)), np.zeros(0)))


def test_a_step_is_not_chosen_from_noise_but_a_real_one_is():
    """The best of some 450 thresholds fits noise: a step's BIC counts the choice of its threshold (2 ln N)."""
    assert threshold_penalty(150) == pytest.approx(2 * np.log(150))
    rng = np.random.default_rng(11)
    from_noise = found = 0
    worst_mm = 0.0
    for _ in range(20):
        best = min(screen_laws(_independent_biases(rng, 0.0), 60), key=lambda law: law.bic)
        from_noise += any(b.startswith("step_") for b in best.basis)
        info = _independent_biases(rng, 0.3)
        best = min(screen_laws(info, 60), key=lambda law: law.bic)
        found += any(b.startswith("step_s@") for b in best.basis)
        info = _independent_biases(rng, 0.15)  # a small step: a step or a smooth law that stands for it
        best = min(screen_laws(info, 60), key=lambda law: law.bic)
        truth = 0.15 * design((step_name("s", 0.5),), info.range_m, info.cos_incidence)[:, 0]
        fitted = design(best.basis, info.range_m, info.cos_incidence) @ best.theta_mm
        worst_mm = max(worst_mm, float(np.sqrt(np.mean((fitted - truth) ** 2))))
    # without the threshold counted: 6 of these 20 noise campaigns get a step
    assert from_noise <= 1, from_noise
    assert found >= 18, found
    assert worst_mm < 0.05, worst_mm


def test_a_disc_just_above_a_strength_step_carries_the_step_it_may_straddle_in_its_sigma():
    """A step of the return strength acts on each return: a disc whose centre is just above the threshold averages
    its weaker rim returns from below it, and its walk lies between the two levels. Half the step at the threshold,
    fading to nothing at four times it; nothing below it, nothing for a step of the incidence or a smooth law."""
    from lidar.systematic.range_walk import RIM_STRENGTH_SHARE, RangeWalkModel

    step = RangeWalkModel(("1", step_name("s", 0.5)), np.array([0.0002, 0.0015]), np.zeros((2, 2)))
    s = np.array([0.3, 0.499, 0.501, 1.0, 0.5 / RIM_STRENGTH_SHARE * 1.01])
    r = 15.0 / np.sqrt(s)  # head-on: strength (15 m / r)^2
    got = step.smear_m(r, np.ones_like(r))
    assert got[0] == 0.0 and got[1] == 0.0 and got[4] == 0.0
    assert got[2] == pytest.approx(0.00075, rel=0.01)
    assert got[3] == pytest.approx(0.00075 * (1 - np.log(2.0) / np.log(1 / RIM_STRENGTH_SHARE)), rel=1e-6)
    for other in (RangeWalkModel(("1", step_name("c", 0.5)), np.array([0.0002, 0.0015]), np.zeros((2, 2))),
                  RangeWalkModel(("1", "sat_strength"), np.array([0.0002, 0.0015]), np.zeros((2, 2)))):
        assert not np.any(other.smear_m(r, np.ones_like(r)))

"""Every range-walk law screened on the linearised adjustment: the same fits as the full one, every threshold."""
from __future__ import annotations

import numpy as np
import pytest

from lidar.simulate.effects import InverseSquareWalk, StrengthStepWalk
from lidar.systematic import adjustment as adj
from lidar.systematic.budget import corrected_displacements
from lidar.systematic.range_walk import PLAUSIBLE_BIC, design, family_spread2, step_name
from lidar.systematic.walk_screen import bias_information, screen_laws
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
    for law in steps[::17]:  # the suffix sums give what the law's own design gives
        chi2, theta = info.chi2(design(law.basis, info.range_m, info.cos_incidence))
        assert law.bic == pytest.approx(chi2 + 2 * np.log(180), rel=1e-9, abs=1e-9)
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

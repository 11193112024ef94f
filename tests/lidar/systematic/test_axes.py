"""The instrument's axis errors: the correction is the simulator's error undone, and the campaign fits them."""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from lidar.simulate.effects import AxisErrors
from lidar.systematic.adjustment import Sighting, VisitSightings, fit_field_model
from lidar.systematic.axes import AxisModel, axis_basis
from lidar.systematic.budget import corrected_displacements
from tests.lidar.systematic.test_field_model import campaign


def test_the_correction_undoes_the_simulators_axis_errors():
    rng = np.random.default_rng(0)
    for collimation, trunnion, index in ((20.0, 0.0, 0.0), (0.0, -35.0, 0.0), (0.0, 0.0, 25.0), (12.0, 30.0, -18.0)):
        err = AxisErrors(collimation_arcsec=collimation, trunnion_arcsec=trunnion, vertical_index_arcsec=index)
        true = rng.uniform([-30, -30, -5], [30, 30, 12], (50, 3))
        r = np.linalg.norm(true, axis=1, keepdims=True)
        reported = err.reported_directions(true / r) * r
        fixed = reported + axis_basis(reported) @ np.array([index, collimation, trunnion])
        assert np.abs(fixed - true).max() < 2e-6  # second order: micrometres at 35 arcsec and 40 m
        assert np.abs(reported - true).max() > 2e-3


def _with_axis_errors(cents, visits, err):
    """The same centroids as an instrument with ``err`` reports them."""
    out_c, out_v = [], []
    for c, v in zip(cents, visits, strict=False):
        new = {}
        for k, x in c.items():
            y = np.asarray(x.xyz_socs)
            r = np.linalg.norm(y)
            new[k] = SimpleNamespace(xyz_socs=err.reported_directions(y[None] / r)[0] * r, cov=x.cov,
                                     cos_incidence=x.cos_incidence, time_s=x.time_s)
        out_c.append(new)
        out_v.append(VisitSightings(v.label, tuple(Sighting(k, x.xyz_socs, x.cov, x.cos_incidence, x.time_s)
                                                   for k, x in new.items())))
    return out_c, out_v


def _z(model, ids, groups, cents, truths):
    out = []
    for k in range(1, len(cents)):
        res = corrected_displacements(cents[0], cents[k], groups, model=model, baseline_label="0", epoch_label=str(k))
        for d in res.displacements:
            j = ids.index(d.reflector)
            out.append((d.displacement_m - (truths[k][j, 2] - truths[0][j, 2])) / d.sigma_m)
    return np.abs(out)


def test_a_vertical_index_error_is_fitted_and_the_displacements_stay_within_their_sigma():
    g, ids, groups, visits, cents, truths = campaign(n=12, seed=5, strain=False)
    err = AxisErrors(vertical_index_arcsec=40.0)
    cents, visits = _with_axis_errors(cents, visits, err)
    model = fit_field_model(visits, groups)
    assert 0 in model.axes.terms  # the vertical index
    value = model.axes.values_arcsec[model.axes.terms.index(0)]
    sigma = np.sqrt(model.axes.covariance_arcsec2[model.axes.terms.index(0)] [model.axes.terms.index(0)])
    assert abs(value - 40.0) < 3 * sigma and sigma < 15.0
    assert _z(model, ids, groups, cents, truths).max() < 3.0
    unfitted = replace(model, axes=AxisModel())  # the same model without them: beyond 3 sigma somewhere
    assert _z(unfitted, ids, groups, cents, truths).max() > 3.0


def test_a_campaign_without_axis_errors_fits_none_or_noise():
    fitted = 0
    for seed in (1, 2, 3, 4):
        g, ids, groups, visits, cents, truths = campaign(n=10, seed=seed)
        axes = fit_field_model(visits, groups).axes
        sigma = np.sqrt(np.diag(axes.covariance_arcsec2))
        assert np.all(np.abs(axes.values_arcsec) < 3 * sigma)  # what BIC lets in is noise within its sigma
        fitted += axes.fitted
    assert fitted <= 2


def test_the_axis_model_survives_its_json():
    m = AxisModel((0, 2), np.array([12.5, -3.0]), np.array([[4.0, 0.5], [0.5, 9.0]]))
    back = AxisModel.from_json(m.to_json())
    assert back.terms == m.terms and np.array_equal(back.values_arcsec, m.values_arcsec)
    assert np.array_equal(back.covariance_arcsec2, m.covariance_arcsec2)
    assert not AxisModel.from_json(None).fitted and not AxisModel.from_json(AxisModel().to_json()).fitted
    assert m.describe().startswith("vertical index +12.5 ± 2.0″; trunnion axis -3.0")
    with pytest.raises(ValueError):
        AxisModel.from_json({"terms": ["wobble"], "values_arcsec": [1.0], "covariance_arcsec2": [[1.0]]})

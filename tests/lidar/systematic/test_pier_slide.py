"""A pier that slides along the span in one visit, with the air logged: the visit is processed, warned once, and
its deck values stay within their sigma; the visits around it get no reference or scale flag."""
from __future__ import annotations

import numpy as np
import pytest

from common.flags import FLAG_ATMOSPHERE_DISAGREES, FLAG_PIER_MOVED, code, severity
from lidar.simulate.epochs import GROUPS, fine_epoch
from lidar.simulate.scene import EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.stage2 import Stage2Inputs, VisitInputs, run_stage2
from lidar.systematic.adjustment import Sighting, VisitSightings
from lidar.systematic.atmosphere import range_scale_ppm
from lidar.systematic.pier_slide import piers
from projects.processing.parameters import DEFAULTS, stage2_params

#: Air temperature of each visit (degC): the instrument keeps a standard atmosphere, so the ranges scale with it.
TEMPERATURES = (10.0, 22.0, -2.0, 15.0, 5.0)
STATIONS = (ScannerSetup((20.6, 11.3, 1.2), heading_deg=138.0), ScannerSetup((19.7, 14.4, 1.2), heading_deg=200.0),
            ScannerSetup((27.2, -12.0, 1.3), heading_deg=322.0), ScannerSetup((20.1, 12.5, 1.3), heading_deg=117.0),
            ScannerSetup((14.0, -10.0, 1.7), heading_deg=85.0))
SLIDING = 3  # the fourth visit: the second pier (R3, R4) slid 3 mm along the span


def _campaign(slide_m: float):
    visits, truths = [], {}
    for k, (temp, station) in enumerate(zip(TEMPERATURES, STATIONS, strict=True)):
        label = f"e{k + 1}"
        cond = EpochConditions(midspan_displacement_m=-0.002 * k, range_scale_ppm=range_scale_ppm(temp),
                               deck_strain=12e-6 * (temp - TEMPERATURES[0]),
                               pier_shifts={1: (slide_m, 0.0, 0.0)} if k == SLIDING else {})
        cents, truth, _, _ = fine_epoch(cond, station, seed=11 + k)
        visits.append(VisitInputs(label, f"stage1-{label}", (1,), (1,), {1: cents}, time_sources={1: "none"},
                                  air=(temp, 1013.25, 0.6)))
        truths[label] = truth
    params = dict(DEFAULTS)
    inputs = Stage2Inputs("e1", tuple(visits), GROUPS, params=params, digest_params=stage2_params(params),
                          order={v.label: n for n, v in enumerate(visits)})
    return run_stage2(inputs), truths


def _normalised_errors(result, truths, label):
    out = []
    for d in result.epoch(label).displacements.displacements:
        true = truths[label].target(d.reflector).vertical_displacement_m - \
            truths["e1"].target(d.reflector).vertical_displacement_m
        out.append((d.displacement_m - true) / d.sigma_m)
    return np.array(out)


@pytest.fixture(scope="module")
def campaigns():
    """The campaign with the pier sliding in the fourth visit, and the same scans' campaign without the slide."""
    return _campaign(0.003), _campaign(0.0)


@pytest.mark.slow
def test_a_pier_sliding_along_the_span_is_named_once_and_the_deck_stays_within_its_sigma(campaigns):
    (result, truths), (still, _) = campaigns
    label = f"e{SLIDING + 1}"
    slid = result.epoch(label).displacements
    moved = [f for f in slid.flags if code(f) == FLAG_PIER_MOVED]
    assert len(moved) == 1 and severity(moved[0]) == "warning"
    assert "R3, R4" in moved[0] and "R1, R2" in moved[0]  # two piers: one moved against the other, both named
    assert not any(code(f) == FLAG_ATMOSPHERE_DISAGREES for f in slid.flags)
    v = result.model.visit(label)
    truth_ppm = range_scale_ppm(TEMPERATURES[SLIDING]) - range_scale_ppm(TEMPERATURES[0])
    assert abs(v.scale_ppm - truth_ppm) <= 2 * v.scale_sigma_ppm  # the slide is not read as the air's scale
    assert abs(abs(v.shift_m) - 0.003) <= 3 * v.shift_sigma_m
    z = _normalised_errors(result, truths, label)
    z_still = _normalised_errors(still, truths, label)  # the same scans had the pier stayed
    assert np.all(np.abs(z) < 3.0) and np.all(np.abs(z - z_still) < 0.5), (z, z_still)
    for e in result.epochs[1:]:  # the visits around it: nothing about piers or the air's scale
        if e.label != label:
            assert not any(code(f) in (FLAG_PIER_MOVED, FLAG_ATMOSPHERE_DISAGREES) for f in e.displacements.flags)
            assert np.all(np.abs(_normalised_errors(result, truths, e.label)) < 3.0)


@pytest.mark.slow
def test_without_a_slide_the_air_explains_every_scale_and_no_pier_is_named(campaigns):
    _, (still, _) = campaigns
    for e in still.epochs:
        assert not any(code(f) in (FLAG_PIER_MOVED, FLAG_ATMOSPHERE_DISAGREES) for f in e.displacements.flags)
        assert not still.model.visit(e.label).shifted


def _sighting(target, xyz):
    return Sighting(target, np.asarray(xyz, dtype=float), np.eye(3) * 1e-8, 1.0)


def test_piers_are_the_reference_targets_grouped_along_the_deck_and_ordered_from_the_first():
    deck = [_sighting(f"M{k}", (35.0 - 7.0 * k, 0.3, 5.0)) for k in range(5)]  # listed from the far end
    refs = [_sighting("R10", (40.0, 0.0, 1.0)), _sighting("R2", (1.0, 1.0, 2.5)), _sighting("R1", (1.0, -1.0, 1.0)),
            _sighting("R3", (19.0, 0.0, 1.0)), _sighting("R4", (21.0, 0.0, 2.5))]
    groups = {s.target: ("reference" if s.target.startswith("R") else "measurement") for s in deck + refs}
    axis, found = piers(VisitSightings("b", tuple(deck + refs)), groups)
    assert found == [("R1", "R2"), ("R3", "R4"), ("R10",)]
    assert axis[0] > 0.99  # away from R1's pier
    assert piers(VisitSightings("b", tuple(deck + refs[1:3])), groups) is None  # one pier only

"""Stage 2 as a pure job: the field model and the displacements from in-memory inputs, no campaign database."""
from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest

from lidar.simulate.epochs import GROUPS, LAB_POSITIONS, fine_epoch
from lidar.simulate.scene import EpochConditions
from lidar.stage2 import Stage2Inputs, VisitInputs, run_stage2
from projects.processing.parameters import DEFAULTS, stage2_params

LOADS_MM = (0.0, -3.0, -6.0)


@pytest.fixture(scope="module")
def campaign():
    """Three visits of the 40 m bridge from three stations, loads 0, -3 and -6 mm at midspan, and their truth."""
    visits, truths = [], {}
    for k, (setup, load) in enumerate(zip(LAB_POSITIONS, LOADS_MM, strict=True)):
        label = f"e{k + 1}"
        cents, truth, _, _ = fine_epoch(EpochConditions(midspan_displacement_m=load / 1000), setup, seed=11 + k)
        visits.append(VisitInputs(label, f"stage1-{label}", (1,), (1,), {1: cents}, time_sources={1: "none"}))
        truths[label] = truth
    return tuple(visits), truths


def _inputs(visits, **kw) -> Stage2Inputs:
    params = dict(DEFAULTS)
    base = Stage2Inputs("e1", visits, GROUPS, params=params, digest_params=stage2_params(params),
                        order={v.label: n for n, v in enumerate(visits)})
    return replace(base, **kw)


@pytest.mark.slow
def test_stage2_runs_on_in_memory_inputs_and_meets_the_truth(campaign):
    visits, truths = campaign
    result = run_stage2(_inputs(visits))
    assert result.labels == ["e1", "e2", "e3"] and result.model_changed
    assert all(e.reason == "new" for e in result.epochs)
    base = result.epoch("e1").displacements
    assert all(d.displacement_m == 0.0 and d.sigma_m == 0.0 for d in base.displacements)
    errors = []
    for label in ("e2", "e3"):
        for d in result.epoch(label).displacements.displacements:
            true = truths[label].target(d.reflector).vertical_displacement_m - \
                truths["e1"].target(d.reflector).vertical_displacement_m
            assert np.isfinite(d.displacement_m) and d.sigma_m > 0
            assert set(d.budget) == {"noise", "frame", "scale", "bias", "drift"}
            errors.append(abs(d.displacement_m - true) / d.sigma_m)
    assert max(errors) < 4.0 and np.mean(np.array(errors) < 2.0) >= 0.8
    assert result.epoch("e3").inputs_hash != result.epoch("e2").inputs_hash


@pytest.mark.slow
def test_stage2_is_incremental_and_says_why_it_recomputes(campaign):
    visits, _ = campaign
    first = run_stage2(_inputs(visits))
    stored = {e.label: e.inputs_hash for e in first.epochs}
    again = run_stage2(_inputs(visits, stored_model=first.model, stored_digests=stored))
    assert again.labels == [] and not again.model_changed  # nothing changed: nothing computed
    params = {**DEFAULTS, "moved_tolerance_m": 0.002}
    changed = run_stage2(_inputs(visits, stored_model=first.model, stored_digests=stored, params=params,
                                 digest_params=stage2_params(params)))
    assert changed.labels == ["e1", "e2", "e3"] and {e.reason for e in changed.epochs} == {"inputs"}
    e2 = replace(visits[1], stage1_digest="stage1-e2-remeasured")  # one visit measured again
    one = run_stage2(_inputs((visits[0], e2, visits[2]), stored_model=first.model, stored_digests=stored))
    assert "e2" in one.labels and "e1" not in one.labels


@pytest.mark.slow
def test_stage2_inputs_travel_to_another_process(campaign):
    """The job is plain values: pickled (as Dask sends it to a worker) it gives the same numbers."""
    visits, _ = campaign
    inputs = _inputs(visits[:2])
    here = run_stage2(inputs)
    there = run_stage2(pickle.loads(pickle.dumps(inputs)))
    a = [d.displacement_m for d in here.epoch("e2").displacements.displacements]
    b = [d.displacement_m for d in there.epoch("e2").displacements.displacements]
    assert np.allclose(a, b, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_the_field_window_keeps_older_visits_and_bounds_the_work(campaign):
    """Issue 44: with ``field_window`` N the model is fitted over the baseline and the newest N visits; an older
    visit keeps its stored values unless its own inputs change (then every visit is fitted again)."""
    from lidar.stage2 import frozen_visits

    visits, _ = campaign
    e4 = replace(visits[2], label="e4", stage1_digest="stage1-e4")  # a fourth visit, the third's scans again
    params = {**DEFAULTS, "field_window": 1}
    kw = dict(params=params, digest_params=stage2_params(params))
    first = run_stage2(_inputs(visits, **kw))
    stored = {e.label: e.inputs_hash for e in first.epochs}
    four = _inputs((*visits, e4), stored_model=first.model, stored_digests=stored, **kw)
    assert frozen_visits(four) == {"e2", "e3"}  # the baseline and the newest (e4) are fitted
    result = run_stage2(four)
    assert "e2" not in result.labels and "e3" not in result.labels and "e4" in result.labels
    assert "e2" not in result.model.visits or result.model.visits.get("e2") == first.model.visits.get("e2")
    moved = {**params, "moved_tolerance_m": 0.002}  # a setting changed: every visit computed again
    again = run_stage2(_inputs((*visits, e4), stored_model=result.model,
                               stored_digests={**stored, **{e.label: e.inputs_hash for e in result.epochs}},
                               params=moved, digest_params=stage2_params(moved)))
    assert again.labels == ["e1", "e2", "e3", "e4"]

"""The station advisor on the layout alone: visibility, ranking and what drives the predicted sigma."""
import math

import numpy as np
import pytest

from common.errors import InputError
from lidar.layout import layout_from_model
from lidar.scanner_catalogue import CATALOGUE
from lidar.simulate import BridgeModel
from lidar.stations import default_area, grid_in_polygon, predict_station, survey_stations

VZ = CATALOGUE["Riegl VZ-1000"]


@pytest.fixture(scope="module")
def layout():
    return layout_from_model(BridgeModel())


def test_a_side_station_sees_every_target(layout):
    p = predict_station(layout, (20.0, -14.0, 1.5), profile=VZ)
    assert not p.hidden and p.usable
    assert set(p.predicted_sigma_mm) == {"M1", "M2", "M3", "M4", "M5"}
    assert all(0.03 < s < 0.3 for s in p.predicted_sigma_mm.values())
    assert all(n >= 900 for n in p.points.values())


def test_hidden_targets_say_why(layout):
    under = predict_station(layout, (20.0, 0.0, 1.5), profile=VZ)  # the VZ's field of view stops 30 deg from zenith
    assert "M3" in under.hidden
    assert "field of view" in under.reasons["M3"]
    beyond = predict_station(layout, (-12.0, -3.0, 1.5), profile=VZ)  # outside the span, behind pier 1
    assert beyond.reasons["R1"] == "faces away"
    assert beyond.reasons["R3"] == "behind a pier"
    panoramic = predict_station(layout, (20.0, 0.0, 1.5), profile=CATALOGUE["FARO Focus Premium"])
    assert "M3" not in panoramic.hidden  # a panoramic scanner looks straight up


def test_sigma_grows_with_distance_and_a_finer_instrument_does_better(layout):
    near = predict_station(layout, (20.0, -12.0, 1.5), profile=VZ)
    far = predict_station(layout, (20.0, -24.0, 1.5), profile=VZ, budget_seconds=36000)
    # same points per target, so the farther station's cost is time and footprint, not sigma alone
    assert far.seconds > near.seconds
    quieter = predict_station(layout, (20.0, -12.0, 1.5), profile=CATALOGUE["Riegl VZ-400i"])
    assert quieter.worst_sigma_mm < near.worst_sigma_mm and quieter.seconds < near.seconds
    # a phase scanner's finest preset cannot put 1000 points on a 50 mm disc at 15 m: it says so
    zf = predict_station(layout, (20.0, -12.0, 1.5), profile=CATALOGUE["Z+F IMAGER 5016"])
    assert max(zf.points.values()) < 1000


def test_survey_ranks_full_visibility_first_and_writes_the_contract(layout):
    area = default_area(layout)
    grid = grid_in_polygon(area, 8.0)
    pos = np.column_stack([grid, np.full(len(grid), 1.5)])
    res = survey_stations(layout, pos, profile=VZ, workers=1)
    assert len(res) == len(pos)
    keys = [s.rank_key() for s in res]
    assert keys == sorted(keys)
    best = res[0]
    assert not best.hidden and math.isfinite(best.worst_sigma_mm)
    d = best.to_json()
    for k in ("x", "y", "z", "seconds", "worst_sigma_mm", "predicted_sigma_mm", "hidden"):
        assert k in d
    assert d["worst_sigma_mm"] == pytest.approx(max(d["predicted_sigma_mm"].values()), abs=1e-4)


def test_bad_areas_and_grids_are_refused():
    with pytest.raises(InputError, match="at least 3"):
        grid_in_polygon(np.array([[0, 0], [1, 1]]), 1.0)
    with pytest.raises(InputError, match="positive"):
        grid_in_polygon(np.array([[0, 0], [10, 0], [0, 10]]), 0.0)
    with pytest.raises(InputError, match="coarser"):
        grid_in_polygon(np.array([[0, 0], [1e4, 0], [0, 1e4]]), 1.0)


def test_surfaces_a_scan_saw_block_the_lines_of_sight_through_them(layout):
    from lidar.stations import Obstacles

    station = np.array([20.0, -14.0, 1.5])
    m3 = layout.xyz[layout.index("M3")]
    # a 1 m x 1 m panel (5 cm sampling) half-way to M3, across the line of sight
    mid = station + 0.5 * (m3 - station)
    g = np.arange(-0.5, 0.5, 0.05)
    panel = np.array([[mid[0] + a, mid[1], mid[2] + b] for a in g for b in g])
    blocked = predict_station(layout, station, profile=VZ, obstacles=Obstacles(panel))
    assert blocked.reasons.get("M3") == "behind something the last scan saw"
    assert "M1" not in blocked.hidden and "R1" not in blocked.hidden
    aside = Obstacles(panel + np.array([0.0, 0.0, 3.0]))
    assert "M3" not in predict_station(layout, station, profile=VZ, obstacles=aside).hidden
    # the surface the target is glued on (the deck's underside around it) does not hide it
    deck = np.array([[m3[0] + a, m3[1] + b, m3[2] + 0.002] for a in g for b in g])
    assert "M3" not in predict_station(layout, station, profile=VZ, obstacles=Obstacles(deck)).hidden


def test_a_weak_targets_predicted_sigma_carries_the_grazing_term_processing_adds():
    from lidar.centroid import grazing_covariance, resolvability
    from lidar.prediction import centroid_covariance

    r, cos = 50.0, 0.12
    xyz = np.array([r, 0.0, 0.0])
    normal = np.array([-cos, 0.0, math.sqrt(1 - cos ** 2)])
    plain = centroid_covariance(xyz, normal, 1000, diameter_m=0.05)
    with_beam = centroid_covariance(xyz, normal, 1000, diameter_m=0.05, profile=VZ)
    q = resolvability(0.05, cos, r, VZ)
    assert 0.2 < q < 0.35
    extra = grazing_covariance(xyz / r, normal, diameter_m=0.05, cos_incidence=cos, footprint_m=VZ.footprint_m(r),
                               ratio=q)
    np.testing.assert_allclose(with_beam - plain, extra, rtol=1e-9, atol=1e-15)
    assert normal @ extra @ normal < 0.02 * np.trace(extra)  # mostly along and across the disc, little in height
    assert np.sqrt(extra[0, 0]) > 1e-3  # millimetres along the line of sight


def test_one_end_of_a_three_span_bridge_the_far_span_is_not_planned_and_says_why():
    lay = layout_from_model(BridgeModel(spans_m=(39.9, 39.9, 39.9), deck_fractions=(0.4, 0.5, 0.6)))
    p = predict_station(lay, (12.0, -11.0, 1.5), profile=VZ)
    far = [t for t, x in zip(lay.ids, lay.xyz, strict=False) if x[0] > 80.0 and t.startswith("M")]
    assert far and all(t not in p.predicted_sigma_mm for t in far)


def test_each_station_says_the_coarse_step_its_targets_need(layout):
    from lidar.plan import coarse_step_needed_deg

    near = predict_station(layout, (20.0, -9.0, 1.5), profile=VZ)
    far = predict_station(layout, (-15.0, -20.0, 1.5), profile=VZ)
    assert 0 < far.coarse_step_deg < near.coarse_step_deg < 0.2
    assert far.to_json()["coarse_step_deg"] == pytest.approx(far.coarse_step_deg, abs=1e-4)
    # a 50 mm disc at 80 deg incidence from 20 m spans 0.025 deg: two samples need 0.0124 deg
    assert coarse_step_needed_deg(0.05, math.cos(math.radians(80)), 20.0) == pytest.approx(0.0124, abs=2e-4)


def test_the_plan_says_which_undetected_targets_the_coarse_step_could_not_resolve():
    from lidar.pipeline import _coarse_step_note
    from lidar.plan import PlanTarget, plan_fine_scans

    targets = [PlanTarget("R1", "reference", (10.0, 0.0, 1.0), 0.05, False, 0.9),
               PlanTarget("M1", "measurement", (30.0, 1.0, 5.0), 0.05, True, 0.15),
               PlanTarget("M2", "measurement", (12.0, 2.0, 5.0), 0.05, True, 0.9)]
    plan = plan_fine_scans(targets)
    note = _coarse_step_note(targets, plan, 0.05)
    assert note is not None and "M1" in note and "M2" not in note and "R1" not in note
    assert _coarse_step_note(targets, plan, 0.005) is None

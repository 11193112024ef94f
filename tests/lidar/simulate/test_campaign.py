"""The campaign generator: stations all round the bridge, random effects, visit folders, a layout with errors."""
import json

import numpy as np
import pytest

from common.errors import InputError
from lidar.io.las import read_las
from lidar.layout import read_layout_csv
from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup, VisitTiming
from lidar.simulate.campaign import (
    campaign_layout,
    random_conditions,
    random_station,
    write_campaign,
)
from lidar.simulate.effects import RANGE_WALK_FORMS
from lidar.simulate.files import conditions_from_dict
from lidar.simulate.visits import truth_plan_for

THREE = BridgeModel(spans_m=(39.9, 39.9, 39.9))


def test_random_stations_stand_on_both_sides_near_the_ends_and_beside_every_span():
    rng = np.random.default_rng(0)
    pos = np.array([random_station(THREE, rng).position_m for _ in range(400)])
    assert np.all(np.abs(pos[:, 1]) >= THREE.deck_width_m / 2 + 8.0)
    assert np.any(pos[:, 1] < 0) and np.any(pos[:, 1] > 0)
    assert np.any(pos[:, 0] < 0.0) and np.any(pos[:, 0] > THREE.length_m)  # beyond either end
    for x0, x1 in zip(THREE.support_x_m[:-1], THREE.support_x_m[1:], strict=False):
        assert np.count_nonzero((pos[:, 0] > x0) & (pos[:, 0] < x1)) > 40
    assert np.all((pos[:, 2] >= 1.2) & (pos[:, 2] <= 1.8))
    with pytest.raises(InputError, match="end_fraction"):
        random_station(THREE, rng, end_fraction=2.0)


def test_random_conditions_turn_every_effect_on_within_its_range():
    rng = np.random.default_rng(1)
    conds = [random_conditions(THREE, rng) for _ in range(60)]
    for c in conds:
        assert len(c.span_displacements_m) == 3 and all(-0.008 <= a <= 0.0 for a in c.span_displacements_m)
        assert abs(c.deck_strain) <= 12e-6 * 15 and abs(c.range_scale_ppm) <= 30.0
        assert 0.0 <= c.clipped_fraction <= 0.3 and c.timed and c.drift is not None
        s = 1.0  # a full disc head-on at 15 m: at most the largest walk
        assert 0.0 < float(c.range_walk.bias_m(15.0, 1.0, s)) <= 0.0015 + 1e-12
    assert {c.range_walk.form for c in conds} == set(RANGE_WALK_FORMS)
    quiet = random_conditions(THREE, rng, max_walk_m=None, drift_arcsec_per_h=0.0)
    assert quiet.range_walk is None and quiet.drift is None


def test_layout_has_centimetre_errors_for_a_multi_span_model(tmp_path):
    lay = campaign_layout(THREE, noise_m=0.03, rng=np.random.default_rng(2))
    assert lay.ids == tuple(t.id for t in THREE.targets)
    err = lay.xyz - np.array([t.centre_m for t in THREE.targets])
    assert 0.01 < np.std(err) < 0.05
    assert len(lay.ids_in("reference")) == 8 and len(lay.ids_in("measurement")) == 18


def test_write_campaign_writes_visit_folders_an_index_and_the_layout(tmp_path):
    model = BridgeModel()
    conds = [EpochConditions(midspan_displacement_m=-0.002, timing=VisitTiming()),
             random_conditions(model, np.random.default_rng(3))]
    stations = [[ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0)],
                [ScannerSetup((10.0, -14.0, 1.5)), ScannerSetup((30.0, 13.0, 1.6), heading_deg=180.0)]]
    visits = write_campaign(tmp_path, model, conds, plan_for=truth_plan_for(min_points=200), stations=stations,
                            coarse_step_deg=0.1, seed=4)
    assert [v.folder for v in visits] == ["visit001", "visit002"]
    one = tmp_path / "visit001"
    assert {p.name for p in one.iterdir()} == {"coarse.laz", "fine.laz", "truth.json", "scene.json"}
    for k in (1, 2):
        assert {p.name for p in (tmp_path / "visit002" / f"setup{k}").iterdir()} >= \
            {"coarse.laz", "fine.laz", "truth.json", "scene.json"}
    assert read_las(one / "fine.laz").time_s is not None
    index = json.loads((tmp_path / "campaign.json").read_text())
    assert [v["folder"] for v in index["visits"]] == ["visit001", "visit002"]
    assert index["visits"][1]["date"].startswith("2026-01-12")
    assert conditions_from_dict(index["visits"][1]["conditions"]) == conds[1]
    assert len(index["visits"][1]["setups"]) == 2
    lay = read_layout_csv(tmp_path / "layout.csv")
    assert lay.ids == tuple(t.id for t in model.targets)
    truth = json.loads((one / "truth.json").read_text())
    assert truth["windows"][0]["name"] == "coarse" and len(truth["windows"]) == 1 + len(model.targets)
    with pytest.raises(InputError, match="stations for"):
        write_campaign(tmp_path / "x", model, conds, plan_for=truth_plan_for(), stations=stations[:1])


def test_random_stations_by_default(tmp_path):
    visits = write_campaign(tmp_path, BridgeModel(), [EpochConditions()], plan_for=lambda folder, coarse: [],
                            coarse_step_deg=0.15, seed=1)
    assert len(visits[0].setups) == 1
    assert (tmp_path / "visit001" / "coarse.laz").is_file() and not (tmp_path / "visit001" / "fine.laz").exists()

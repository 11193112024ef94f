"""Visit files: scene specs, timed visits in scan order, closure windows, several set-ups, project-frame exports."""
import json
from dataclasses import replace

import numpy as np
import pytest

from common.errors import InputError
from lidar.io.las import read_las
from lidar.plan import RoiPlan
from lidar.simulate import (
    AxisErrors,
    BridgeModel,
    DriftModel,
    EpochConditions,
    LogisticStrengthWalk,
    ScannerSetup,
    VisitTiming,
)
from lidar.simulate.effects import IntensityModel
from lidar.simulate.files import load_scene, load_scene_model, save_scene, scan_order, simulate_coarse
from lidar.simulate.visits import (
    export_registered,
    project_transform,
    read_sop,
    simulate_setups,
    simulate_visit,
    truth_plan_for,
    write_sop,
)

SETUP = ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0, pitch_deg=0.03, roll_deg=-0.02)
STEP = 0.1  # a coarse coarse scan: these tests are about the files, not the points


def test_default_scene_spec_is_written_as_before(tmp_path):
    save_scene(tmp_path, SETUP, EpochConditions(midspan_displacement_m=-0.002, cable_ties=("R1",)), 3, 0.04)
    d = json.loads((tmp_path / "scene.json").read_text())
    assert d["format_version"] == 1 and "model" not in d
    assert list(d) == ["format_version", "setup", "conditions", "seed", "coarse_step_deg"]
    assert list(d["conditions"]) == ["midspan_displacement_m", "moved_targets", "occluded", "cable_ties", "removed",
                                     "saturated"]
    save_scene(tmp_path, SETUP, EpochConditions(), 3, 0.04, model=BridgeModel())
    assert "model" not in json.loads((tmp_path / "scene.json").read_text())


def test_scene_spec_round_trips_the_model_and_every_effect(tmp_path):
    model = BridgeModel(spans_m=(30.0, 40.0, 30.0), deflection_shape="continuous", deck_width_m=8.0)
    cond = EpochConditions(span_displacements_m=(-0.002, -0.004, -0.001), deck_strain=2.4e-4, fixed_bearing_x_m=30.0,
                           range_scale_ppm=-18.0, range_scale_rate_ppm_h=7.5,
                           range_walk=LogisticStrengthWalk(0.001, 0.4, 0.1),
                           clipped_fraction=0.15, drift=DriftModel(3.0, -2.0, 5.0, 0.5, jump_y_arcsec=12.0,
                                                                   jump_after_s=600.0),
                           timing=VisitTiming(start_s=345_600.0, gap_s=12.0, rate_hz=50_000.0, duration="lines"),
                           axis_errors=AxisErrors(collimation_arcsec=9.0, range_offset_m=0.002),
                           walk_factors={"M3": 1.6}, intensity_model=IntensityModel("db", floor_db=-25.0))
    save_scene(tmp_path, SETUP, cond, 9, 0.05, model=model)
    setup, back, seed, step = load_scene(tmp_path)
    assert (setup, back, seed, step) == (SETUP, cond, 9, 0.05)
    assert load_scene_model(tmp_path) == model
    assert json.loads((tmp_path / "scene.json").read_text())["format_version"] == 2


def test_closure_flag_is_in_plan_json_only_when_true():
    from lidar.angles import AngularWindow

    roi = RoiPlan("R1", "reference", AngularWindow(10.0, 11.0, 80.0, 81.0, 0.01, 0.01), 20.0, 10.0, 100, 50, 4.0)
    assert "closure" not in roi.to_json()
    closing = replace(roi, closure=True)
    assert closing.to_json()["closure"] is True
    assert RoiPlan.from_json(closing.to_json()).closure and not RoiPlan.from_json(roi.to_json()).closure
    assert [r.closure for r in scan_order([closing, roi])] == [False, True]


def test_timed_visit_scans_coarse_then_windows_in_plan_order_then_closure(tmp_path):
    timing = VisitTiming(start_s=1000.0, gap_s=20.0)
    cond = EpochConditions(midspan_displacement_m=-0.003, timing=timing, drift=DriftModel(tilt_x_arcsec_per_h=20.0))
    plan = truth_plan_for(min_points=300, closure="R1")

    def closure_first(folder, coarse):
        rois = plan(folder, coarse)
        return [rois[-1]] + rois[:-1]  # the closure window listed first: still scanned last

    v = simulate_visit(tmp_path, setup=SETUP, conditions=cond, plan_for=closure_first, coarse_step_deg=STEP)
    names = [w.name for w in v.truth.windows]
    assert names == ["coarse", "R1", "R2", "R3", "R4", "M1", "M2", "M3", "M4", "M5", "R1"]
    assert [w.closure for w in v.truth.windows] == [False] * 10 + [True]
    w = v.truth.windows
    assert w[0].start_s == 1000.0
    for a, b in zip(w[:-1], w[1:], strict=False):
        assert b.start_s == pytest.approx(a.end_s + 20.0)
    coarse, fine = read_las(v.coarse), read_las(v.fine)
    assert np.all(np.diff(coarse.time_s) > 0) and np.all(np.diff(fine.time_s) > 0)
    assert coarse.time_s.max() < fine.time_s.min()
    assert w[0].start_s <= coarse.time_s.min() and coarse.time_s.max() < w[0].end_s
    assert fine.time_s.max() < w[-1].end_s and fine.time_s.min() >= w[1].start_s
    # every target's time lies in its own (first) window
    spans = {x.name: x for x in w[1:-1]}
    for t in v.truth.targets:
        assert spans[t.id].start_s < t.time_s < spans[t.id].end_s
    saved = json.loads((tmp_path / "truth.json").read_text())
    assert saved["format_version"] == 2 and len(saved["windows"]) == 11 and saved["drift"]["tilt_x_arcsec_per_h"] == 20


def test_untimed_visit_has_no_times(tmp_path):
    v = simulate_visit(tmp_path, setup=SETUP, conditions=EpochConditions(), plan_for=truth_plan_for(min_points=200),
                       coarse_step_deg=STEP)
    assert read_las(v.fine).time_s is None and v.truth.windows == ()
    assert v.truth.target("M3").time_s is None


def test_multi_span_visit_uses_the_model_of_its_scene(tmp_path):
    model = BridgeModel(spans_m=(25.0, 25.0))
    setup = ScannerSetup((25.0, -14.0, 1.5), heading_deg=10.0)
    v = simulate_visit(tmp_path, setup=setup, conditions=EpochConditions(span_displacements_m=(-0.003, -0.002)),
                       plan_for=truth_plan_for(min_points=200), model=model, coarse_step_deg=STEP)
    assert load_scene_model(tmp_path) == model
    assert {t.id for t in v.truth.targets} == {t.id for t in model.targets}
    seen = [t for t in v.truth.targets if t.points_on_target]
    assert len(seen) >= 10


def test_several_setups_in_one_visit(tmp_path):
    setups = [SETUP, ScannerSetup((22.0, 13.0, 1.6), heading_deg=200.0)]
    cond = EpochConditions(timing=VisitTiming(start_s=0.0), drift=DriftModel(twist_arcsec_per_h=30.0))
    visits = simulate_setups(tmp_path, setups, cond, plan_for=truth_plan_for(min_points=200), coarse_step_deg=STEP,
                             move_s=900.0)
    assert [v.folder.name for v in visits] == ["setup1", "setup2"]
    for v, s in zip(visits, setups, strict=False):
        assert (v.folder / "coarse.laz").is_file() and (v.folder / "fine.laz").is_file()
        np.testing.assert_allclose(v.truth.scanner_pose, s.pose)
    end1 = max(w.end_s for w in visits[0].truth.windows)
    assert visits[1].truth.windows[0].start_s == pytest.approx(end1 + 900.0)
    assert load_scene(visits[1].folder)[1].timing.start_s == pytest.approx(end1 + 900.0)
    with pytest.raises(InputError, match="no set-ups"):
        simulate_setups(tmp_path, [], cond, plan_for=truth_plan_for())


def test_registered_export_writes_project_coordinates_and_the_sop(tmp_path):
    cond = EpochConditions(timing=VisitTiming())
    v = simulate_visit(tmp_path / "v", setup=SETUP, conditions=cond, plan_for=truth_plan_for(min_points=200),
                       coarse_step_deg=STEP)
    sop = project_transform(np.random.default_rng(4), tilt_deg=0.5)
    assert abs(sop[0, 3] - 2_500_000.0) < 60 and abs(sop[1, 3] - 5_600_000.0) < 60
    out = export_registered(v.folder, tmp_path / "project", sop)
    text = out["sop"].read_text().splitlines()
    assert text[0].startswith("#") and len([line for line in text if not line.startswith("#")]) == 4
    np.testing.assert_allclose(read_sop(out["sop"]), sop, atol=1e-6)
    for name in ("coarse.laz", "fine.laz"):
        socs, proj = read_las(v.folder / name), read_las(out[name])
        assert proj.pose is None
        np.testing.assert_allclose(proj.xyz_socs, socs.xyz_socs @ sop[:3, :3].T + sop[:3, 3], atol=2e-5, rtol=0)
        np.testing.assert_array_equal(proj.time_s, socs.time_s)
    assert (tmp_path / "project" / "truth.json").is_file()
    with pytest.raises(InputError, match="rigid"):
        export_registered(v.folder, tmp_path / "bad", np.diag([2.0, 1.0, 1.0, 1.0]))
    write_sop(tmp_path / "bad.txt", sop)
    (tmp_path / "bad.txt").write_text("# x\n1 2 3\n")
    with pytest.raises(InputError, match="4 rows"):
        read_sop(tmp_path / "bad.txt")


def test_coarse_scan_alone_is_timed_from_the_start(tmp_path):
    cond = EpochConditions(timing=VisitTiming(start_s=50.0, rate_hz=100_000.0))
    path, truth = simulate_coarse(tmp_path, setup=SETUP, conditions=cond, coarse_step_deg=STEP)
    t = read_las(path).time_s
    assert t.min() >= 50.0 and truth.windows[0].name == "coarse" and truth.windows[0].start_s == 50.0

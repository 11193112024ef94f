import json

import numpy as np
import pytest

from common.errors import InputError
from lidar.plan import PlanTarget, ScanPlan, choose_steps, plan_fine_scans
from lidar.scanner_profile import VZ1000, ScannerProfile
from lidar.simulate import EpochConditions
from tests.lidar.sim_helpers import LAB_POSITIONS, fine_epoch

CONTRACT_FIELDS = {"reflector", "group", "phi_min_deg", "phi_max_deg", "theta_min_deg", "theta_max_deg",
                   "phi_step_deg", "theta_step_deg", "range_m", "expected_points", "expected_seconds"}


def target(theta=80.0, phi=10.0, r=20.0, **kw):
    t, p = np.radians(theta), np.radians(phi)
    xyz = (r * np.sin(t) * np.cos(p), r * np.sin(t) * np.sin(p), r * np.cos(t))
    return PlanTarget(kw.pop("id", "T1"), kw.pop("group", "measurement"), xyz, incidence_cos=kw.pop("cos", 1.0), **kw)


def test_steps_respect_instrument_limits_and_point_target():
    omega = np.pi * 0.025 ** 2 / 20 ** 2
    dt, dp = choose_steps(omega, 1.0, 1000, VZ1000)
    assert dt >= VZ1000.min_theta_step_deg and dp >= VZ1000.min_phi_step_deg
    points = omega / (np.radians(dt) * np.radians(dp))
    assert points >= 1000


def test_plan_json_contract_and_round_trip(tmp_path):
    plan = plan_fine_scans([target(id="A"), target(phi=0.01, id="B", group="reference")], epoch="2026-01-05")
    path = plan.save(tmp_path / "plan.json")
    d = json.loads(path.read_text())
    assert {"epoch", "scanner_profile", "total_seconds", "rois"} <= d.keys()
    for roi in d["rois"]:
        assert CONTRACT_FIELDS <= roi.keys()
        assert roi["phi_min_deg"] < roi["phi_max_deg"]
    seam = d["rois"][1]
    assert seam["phi_min_deg"] < 0 < seam["phi_max_deg"]  # a window across 0 deg starts below 0
    assert d["total_seconds"] == pytest.approx(sum(r["expected_seconds"] for r in d["rois"]), abs=0.05)
    back = ScanPlan.load(path)
    assert [r.reflector for r in back.rois] == ["A", "B"]
    assert back.rois[1].window == plan.rois[1].window


def test_line_scanner_time_depends_on_lines_not_kept_points():
    prof = ScannerProfile()
    near = plan_fine_scans([target(r=10.0)]).rois[0]
    assert near.expected_seconds == pytest.approx(
        prof.window_seconds(near.window.phi_max_deg - near.window.phi_min_deg, near.window.phi_step_deg,
                            near.window.theta_step_deg))


def test_over_budget_trades_points_for_time_and_says_so():
    targets = [target(phi=5 * k, id=f"T{k}") for k in range(12)]
    full = plan_fine_scans(targets, min_points=1000, budget_seconds=1e6)
    tight = plan_fine_scans(targets, min_points=1000, budget_seconds=full.total_seconds / 3)
    assert tight.total_seconds <= full.total_seconds / 3 + 1e-6
    assert tight.points_per_target < 1000
    assert any("reduced" in w for w in tight.warnings)
    assert not full.warnings


def test_bad_plan_inputs(tmp_path):
    with pytest.raises(InputError):
        plan_fine_scans([])
    with pytest.raises(InputError):
        plan_fine_scans([target()], min_points=2)
    (tmp_path / "p.json").write_text("{not json")
    with pytest.raises(InputError, match="not a JSON plan"):
        ScanPlan.load(tmp_path / "p.json")
    (tmp_path / "q.json").write_text(json.dumps({"rois": [{"reflector": "A"}]}))
    with pytest.raises(InputError, match="missing the field"):
        ScanPlan.load(tmp_path / "q.json")
    (tmp_path / "r.json").write_text(json.dumps({"format_version": 99, "rois": []}))
    with pytest.raises(InputError, match="newer"):
        ScanPlan.load(tmp_path / "r.json")


@pytest.mark.slow
def test_plan_expected_points_match_what_the_simulator_delivers():
    cents, truth, plan, fine = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=11)
    from lidar.angles import spherical_from_xyz

    theta, phi, _ = spherical_from_xyz(fine.xyz_socs)
    for roi in plan.rois:
        delivered_target = truth.target(roi.reflector).points_on_target
        assert delivered_target == pytest.approx(roi.expected_target_points, rel=0.30), roi.reflector
        in_window = np.count_nonzero(roi.window.contains(theta, phi))
        assert in_window == pytest.approx(roi.expected_points, rel=0.30), roi.reflector


def _cos_for(q, r, profile=VZ1000, d=0.05):
    """The incidence cosine at which a disc of diameter d at range r is q of the beam's width."""
    return q * float(profile.footprint_m(r)) / d


def test_weak_targets_take_only_the_time_left_and_never_shrink_another_window():
    from lidar.centroid import UNRESOLVED_RATIO, WEAK_RATIO, resolvability

    strong = [target(phi=5 * k, id=f"S{k}") for k in range(4)]
    weak = [target(phi=30 + 2 * k, r=50.0, id=f"W{k}", cos=_cos_for(q, 50.0)) for k, q in enumerate((0.3, 0.25))]
    narrow = target(phi=40, r=50.0, id="N", cos=_cos_for(0.12, 50.0))
    for t in weak:
        assert UNRESOLVED_RATIO <= resolvability(0.05, t.incidence_cos, 50.0, VZ1000) < WEAK_RATIO
    alone = plan_fine_scans(strong, budget_seconds=3600)
    plan = plan_fine_scans(strong + weak + [narrow], budget_seconds=3600)
    by_id = {r.reflector: r for r in plan.rois}
    assert {"W0", "W1"} <= by_id.keys() and "N" not in by_id
    assert dict(plan.skipped)["N"].endswith("of the beam's width")
    for r in alone.rois:  # the strong windows are exactly those planned without the weak ones
        assert by_id[r.reflector].expected_points == r.expected_points
    assert all(any(n.startswith("weak:") for n in by_id[w].notes) for w in ("W0", "W1"))
    # a budget with room for the strong windows and one weak one: the more resolvable one gets it
    w0 = by_id["W0"].expected_seconds
    tight = plan_fine_scans(strong + weak, budget_seconds=alone.total_seconds + w0 + 1.0)
    ids = [r.reflector for r in tight.rois]
    assert "W0" in ids and "W1" not in ids
    assert "no time is left" in dict(tight.skipped)["W1"]
    assert any("no time left in the budget): W1" in w for w in tight.warnings)
    assert tight.points_per_target == alone.points_per_target and tight.total_seconds <= tight.budget_seconds


def test_closure_keeps_its_time_when_weak_windows_fill_the_budget():
    strong = [target(phi=5 * k, id=f"S{k}", group="reference" if k == 0 else "measurement") for k in range(3)]
    weak = [target(phi=30 + 2 * k, r=50.0, id=f"W{k}", cos=_cos_for(0.3, 50.0)) for k in range(6)]
    alone = plan_fine_scans(strong, budget_seconds=3600, closure=True)
    plan = plan_fine_scans(strong + weak, budget_seconds=alone.total_seconds + 200.0, closure=True)
    assert plan.rois[-1].closure
    assert plan.total_seconds <= plan.budget_seconds * 1.0001


def test_only_weak_targets_are_still_planned():
    plan = plan_fine_scans([target(r=50.0, id="W", cos=_cos_for(0.3, 50.0))])
    assert [r.reflector for r in plan.rois] == ["W"]
    assert any(n.startswith("weak:") for n in plan.rois[0].notes)


def test_reference_targets_get_more_points_from_the_time_the_others_leave():
    """Every value of a visit is referred to its reference targets: they get reference_factor times the points
    where the budget allows, never at the deck targets' expense."""
    refs = [target(phi=5 * k, r=10.0, id=f"R{k}", group="reference") for k in range(4)]
    deck = [target(phi=3 + 5 * k, r=15.0, id=f"M{k}") for k in range(5)]
    plain = plan_fine_scans(refs + deck, budget_seconds=1e6)
    more = plan_fine_scans(refs + deck, budget_seconds=1e6, reference_factor=4.0)
    pts = {r.reflector: r.expected_target_points for r in plain.rois}
    got = {r.reflector: r.expected_target_points for r in more.rois}
    assert all(got[f"R{k}"] >= 3.5 * pts[f"R{k}"] for k in range(4)), (pts, got)
    assert all(got[f"M{k}"] == pts[f"M{k}"] for k in range(5))
    assert more.total_seconds > plain.total_seconds and not more.warnings
    # a budget between the two: the deck keeps its points, the reference targets get what is left
    mid = plan_fine_scans(refs + deck, budget_seconds=0.5 * (plain.total_seconds + more.total_seconds),
                          reference_factor=4.0)
    got = {r.reflector: r.expected_target_points for r in mid.rois}
    assert all(got[f"M{k}"] == pts[f"M{k}"] for k in range(5))
    assert all(pts[f"R{k}"] < got[f"R{k}"] < 4 * pts[f"R{k}"] for k in range(4)) and not mid.warnings
    assert mid.total_seconds <= 0.5 * (plain.total_seconds + more.total_seconds) + 1e-6
    # too short even for min_points: the same plan as without the factor
    tight = plan_fine_scans(refs + deck, budget_seconds=plain.total_seconds / 2, reference_factor=4.0)
    assert [r.expected_target_points for r in tight.rois] == \
        [r.expected_target_points for r in plan_fine_scans(refs + deck, budget_seconds=plain.total_seconds / 2).rois]
    with pytest.raises(InputError, match="factor"):
        plan_fine_scans(refs + deck, reference_factor=0.5)

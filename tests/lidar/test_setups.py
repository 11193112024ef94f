"""Joining the set-ups of a visit: the multi-station adjustment, its refusals, and the budget over joined set-ups."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common.flags import FLAG_SETUP_JOIN_MISFIT, FLAG_SETUP_JOIN_WEAK, FLAG_SETUP_NOT_JOINED, code
from lidar.displacement_result import Observation
from lidar.setups import (
    CorrectedVisit,
    corrected_side,
    join_setups,
    joined_displacements,
    spread_m,
    visit_label,
)
from lidar.simulate.epochs import GROUPS, LAB_POSITIONS, fine_epoch
from lidar.simulate.scene import EpochConditions
from lidar.systematic.adjustment import FieldModel, VisitSystematics
from lidar.systematic.budget import corrected_displacements
from lidar.systematic.range_walk import RangeWalkModel

RNG = np.random.default_rng(7)
#: A three-span bridge's targets in set-up 1's frame (m): piers at 0, 40, 80, 120, deck targets in every span.
TARGETS = {f"R{k}": np.array([x, y, z]) for k, (x, y, z) in enumerate(
    [(1, -1.5, 2), (1, 1.5, 5), (39, 1.5, 5), (41, -1.5, 2), (79, 1.5, 5), (81, -1.5, 2), (119, 1.5, 2), (119, -1.5, 5)],
    start=1)}
TARGETS.update({f"M{k}": np.array([x, y, 7.0]) for k, (x, y) in enumerate(
    [(x0 + f, y) for x0 in (0, 40, 80) for y in (-1.5, 1.5) for f in (16, 20, 24)], start=1)})
MOTION = Rotation.from_euler("zyx", [130.0, 0.02, -0.03], degrees=True).as_matrix(), np.array([95.0, -4.0, 0.1])


def _cov(sigma_mm: float) -> np.ndarray:
    return np.diag([1.0, 1.5, 0.7]) * (sigma_mm * 1e-3) ** 2


def _sides(seen1, seen2, *, sigma1=0.1, sigma2=0.1, noise=True, offset=None):
    """Observations of set-up 1 (the frame) and set-up 2 (rotated and moved by MOTION), with noise."""
    rot, tr = MOTION
    s1, s2 = {}, {}
    for t in seen1:
        c = _cov(sigma1)
        s1[t] = Observation(TARGETS[t] + (RNG.multivariate_normal(np.zeros(3), c, method="cholesky") if noise else 0), c)
    for t in seen2:
        c = _cov(sigma2)
        y = rot.T @ (TARGETS[t] - tr) + (RNG.multivariate_normal(np.zeros(3), c, method="cholesky") if noise else 0)
        if offset and t in offset:
            y = y + offset[t]
        s2[t] = Observation(y, c)
    return {1: s1, 2: s2}


END1 = ["R1", "R2", "R3", "M1", "M2", "M3", "M4", "M5", "M6", "M7", "M8", "M9", "M10", "M11", "M12"]
END2 = ["R4", "R5", "R6", "R7", "R8", "M7", "M8", "M9", "M10", "M11", "M12", "M13", "M14", "M15", "M16", "M17", "M18"]


def test_visit_labels_of_set_ups():
    assert visit_label("v1", 1) == "v1" and visit_label("v1", 3) == "v1#3"


def test_the_join_recovers_the_motion_and_places_every_target():
    j = join_setups("v1", _sides(END1, END2))
    assert j.joined == (1, 2) and not j.refused and not j.flags()
    assert sorted(j.targets) == sorted(set(END1) | set(END2))
    err = np.array([j.positions[j.targets.index(t)] - TARGETS[t] for t in j.targets])
    sig = np.sqrt(np.array([np.diag(j.covariance)[3 * i:3 * i + 3] for i in range(len(j.targets))]))
    assert np.all(np.abs(err) < 5 * sig)  # every position within 5 sigma of the truth
    m = j.motions[2]
    angle = np.linalg.norm(Rotation.from_matrix(m["rotation"] @ MOTION[0].T).as_rotvec())
    sd = np.sqrt(np.diag(m["cov"]))
    assert 0 < angle < 5 * np.linalg.norm(sd[:3]) < 5e-4  # within its sigma, and that sigma tens of microradians
    assert np.linalg.norm(m["translation"] - MOTION[1]) < 5 * np.linalg.norm(sd[3:]) < 0.01
    assert sorted(m["shared"]) == ["M10", "M11", "M12", "M7", "M8", "M9"] and m["spread_m"] > 1.0
    doc = j.to_json()
    assert doc["joined"] == [1, 2] and doc["motions"][0]["rotation_sigma_arcsec"] > 0
    assert {r["reflector"] for r in doc["residuals"]} == set(m["shared"])


def test_a_target_seen_twice_is_measured_once_combined_by_covariance():
    sides = _sides(END1, END2, sigma2=0.3)
    j = join_setups("v1", sides)
    i = j.targets.index("M8")
    cov = j.covariance[3 * i:3 * i + 3, 3 * i:3 * i + 3]
    rot = j.motions[2]["rotation"]
    c1, c2 = sides[1]["M8"].cov, rot @ sides[2]["M8"].cov @ rot.T
    combined = np.linalg.inv(np.linalg.inv(c1) + np.linalg.inv(c2))
    assert np.all(np.diag(cov) < np.diag(c1)) and np.all(np.diag(cov) >= np.diag(combined) * 0.999)
    # the gain: a set-up-1-only target depends on its own centroid alone (weight 1), a set-up-2-only one on the motion too
    k1 = j.sightings.index((1, "M1"))
    assert np.allclose(j.gain[3 * j.targets.index("M1"):3 * j.targets.index("M1") + 3, 3 * k1:3 * k1 + 3], np.eye(3),
                       atol=1e-9)
    k2 = j.sightings.index((1, "M9"))
    assert np.any(np.abs(j.gain[3 * j.targets.index("M15"):3 * j.targets.index("M15") + 3, 3 * k2:3 * k2 + 3]) > 1e-3)


def test_set_ups_sharing_too_little_are_refused_with_the_reason():
    j = join_setups("v1", _sides(["R1", "R2", "M1", "M2", "M7", "M8"], ["M7", "M8", "M13", "M14", "R7", "R8"]))
    assert j.joined == (1,) and 2 in j.refused and "shares 2 target(s)" in j.refused[2]
    assert "M13" not in j.targets
    (flag,) = j.flags()
    assert code(flag) == FLAG_SETUP_NOT_JOINED and "set-up 2" in flag
    line = join_setups("v1", _sides(["R1", "M1", "M2", "M3", "M7", "M8", "M9"], ["M7", "M8", "M9", "M13", "R8"]))
    assert 2 in line.refused and "on a line" in line.refused[2]  # M7, M8, M9 lie along one girder line


def test_a_shared_target_whose_sightings_disagree_is_left_out_of_the_motion():
    off = {"M10": np.array([0.0, 0.004, 0.0])}  # 4 mm off in set-up 2's view: a wrong centroid
    j = join_setups("v1", _sides(END1, END2, sigma2=0.15, offset=off))
    assert j.left_out == ((2, "M10"),)
    (flag,) = j.flags()
    assert code(flag) == FLAG_SETUP_JOIN_MISFIT and "M10 from set-up 2" in flag
    i = j.targets.index("M10")
    assert np.linalg.norm(j.positions[i] - TARGETS["M10"]) < 1e-3  # from set-up 1's sighting


def test_one_set_up_is_its_own_join():
    sides = _sides(END1, [])
    j = join_setups("v1", {1: sides[1]})
    assert np.allclose(j.gain, np.eye(3 * len(END1)), atol=1e-9)
    for t, o in j.observations().items():
        assert np.allclose(o.xyz, sides[1][t].xyz, atol=1e-12) and np.allclose(o.cov, sides[1][t].cov, rtol=1e-9)


def test_spread_of_shared_targets():
    assert spread_m(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 1e-9]])) < 1e-6
    assert spread_m(np.array([TARGETS[t] for t in ("M7", "M8", "M10", "M11")])) > 1.0


def _model(labels) -> FieldModel:
    """A field model with a range walk, scales and drifts that do not vanish, for the budget."""
    rw = RangeWalkModel(("1", "cos"), np.array([3e-4, -2e-4]), np.array([[4e-8, 1e-8], [1e-8, 9e-8]]), True, (),
                        ((("1", "cos"), np.array([3e-4, -2e-4]), 1.0), (("1",), np.array([2e-4]), 0.4)))
    visits = {lab: VisitSystematics(lab, 0.0 if k == 0 else 4.0 * k, 0.0 if k == 0 else 2.5, np.array([1.0, -2.0, 0.5]),
                                    np.diag([4.0, 9.0, 1.0]), 100.0, True, True, (), (0.0, 1.0) if k else (), 1.2)
              for k, lab in enumerate(labels)}
    return FieldModel(labels[0], rw, visits)


def test_the_joined_budget_of_single_set_ups_is_the_field_budget():
    """One set-up a side: the join is the identity, and every term equals corrected_displacements'."""
    base, _, _, _ = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=1)
    ep, _, _, _ = fine_epoch(EpochConditions(midspan_displacement_m=-0.004), LAB_POSITIONS[1], seed=2)
    t = 1000.0
    base = {k: _timed(v, t + 10 * n) for n, (k, v) in enumerate(sorted(base.items()))}
    ep = {k: _timed(v, t + 12 * n) for n, (k, v) in enumerate(sorted(ep.items()))}
    model = _model(["b", "e"])
    want = corrected_displacements(base, ep, GROUPS, model=model, baseline_label="b", epoch_label="e")
    got = joined_displacements(corrected_side("b", {1: base}, model), corrected_side("e", {1: ep}, model), GROUPS,
                               model=model)
    assert isinstance(corrected_side("b", {1: base}, model), CorrectedVisit)
    for a, b in zip(want.displacements, got.displacements, strict=False):
        assert a.reflector == b.reflector and a.displacement_m == pytest.approx(b.displacement_m, abs=1e-12)
        assert b.sigma_m == pytest.approx(a.sigma_m, rel=1e-6)
        assert b.along_sigma_m == pytest.approx(a.along_sigma_m, rel=1e-6)
        for k in a.budget:
            assert b.budget[k] == pytest.approx(a.budget[k], rel=1e-5, abs=1e-9), (a.reflector, k)


def _timed(c, t):
    from dataclasses import replace

    return replace(c, time_s=float(t))


def test_two_set_ups_a_side_give_the_displacements_of_one_frame():
    """The same targets seen from two set-ups (set-up 2 = set-up 1's view moved by MOTION) join to set-up 1's."""
    base, _, _, _ = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=3)
    ep, _, _, _ = fine_epoch(EpochConditions(midspan_displacement_m=-0.004), LAB_POSITIONS[2], seed=4)
    rot, tr = MOTION
    from dataclasses import replace

    moved = {k: replace(v, xyz_socs=rot.T @ (np.asarray(v.xyz_socs) - tr), cov=rot.T @ v.cov @ rot,
                        normal_socs=rot.T @ np.asarray(v.normal_socs)) for k, v in ep.items()}
    first = {k: v for k, v in ep.items() if k in ("R1", "R2", "M1", "M2", "M3")}
    second = {k: v for k, v in moved.items() if k not in ("M1",)}
    model = FieldModel("b", RangeWalkModel(), {})
    one = corrected_displacements(base, ep, GROUPS, model=model, baseline_label="b", epoch_label="e")
    side = corrected_side("e", {1: first, 2: second}, model)
    assert side.join.joined == (1, 2)
    two = joined_displacements(corrected_side("b", {1: base}, model), side, GROUPS, model=model)
    for a, b in zip(one.displacements, two.displacements, strict=False):
        assert b.displacement_m == pytest.approx(a.displacement_m, abs=3 * b.sigma_m)
        assert set(b.budget) == {"noise", "frame", "scale", "bias", "drift"}
        assert b.sigma_m == pytest.approx(np.sqrt(sum(v ** 2 for v in b.budget.values())), rel=1e-9)


def test_sightings_that_disagree_beyond_their_covariances_widen_what_the_join_hands_on():
    """sigma0 > 1: the budget's sighting covariances scaled by sigma0**2 (the a posteriori variance factor), never shrunk."""
    agree = join_setups("v1", _sides(END1, END2, noise=False))
    assert agree.sigma0 < 1e-3
    np.testing.assert_allclose(agree.sighting_cov[0], _cov(0.1))  # agreeing better than said: left as said
    rng = np.random.default_rng(3)
    shared = ["M7", "M8", "M9", "M10", "M11", "M12"]
    offset = {t: rng.normal(0.0, 0.25e-3, 3) for t in shared}  # about twice the sightings' sigma
    loose = join_setups("v1", _sides(END1, END2, noise=False, offset=offset))
    assert loose.sigma0 > 1.3
    np.testing.assert_allclose(loose.sighting_cov[0], _cov(0.1) * loose.sigma0 ** 2)
    # the weights stay as measured: the positions' covariance is the gain over the unscaled sightings
    assert np.trace(loose.covariance) == pytest.approx(np.trace(agree.covariance), rel=0.05)  # not sigma0**2 more


def test_a_weak_sighting_is_left_out_where_another_set_up_sees_the_target_better():
    from types import SimpleNamespace

    from lidar.centroid import is_weak, resolved_share
    from lidar.setups import without_weak_duplicates

    weak = SimpleNamespace(flags=("grazing: the disc is 24 % of the beam's width",))
    grazing = SimpleNamespace(flags=("second_bright_object", "grazing: the disc is 52 % of the beam's width"))
    sharp = SimpleNamespace(flags=())
    assert resolved_share(weak.flags) == pytest.approx(0.24) and is_weak(weak.flags)
    assert not is_weak(grazing.flags) and resolved_share(sharp.flags) == 1.0
    kept = without_weak_duplicates({1: {"M7": weak, "M13": weak, "M1": sharp},
                                    2: {"M7": grazing, "M1": weak, "M14": weak}})
    assert kept == {1: {"M13": weak, "M1": sharp}, 2: {"M7": grazing, "M14": weak}}  # weak alone: still measured


def test_a_set_up_joined_through_weak_sightings_is_flagged_with_them():
    """Issue 40: beside the inner piers of the four-span steel-like deck the set-ups shared only targets both saw
    at grazing incidence; the join rested on them, every value of set-up 2 was 0.6-0.8 mm off (within its sigma)
    and nothing on the visit said why. Fewer than three targets seen well from both sides: flagged, naming them."""
    from dataclasses import replace

    ep, _, _, _ = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=4)
    rot, tr = MOTION
    moved = {k: replace(v, xyz_socs=rot.T @ (np.asarray(v.xyz_socs) - tr), cov=rot.T @ v.cov @ rot,
                        normal_socs=rot.T @ np.asarray(v.normal_socs)) for k, v in ep.items()}
    first = {k: v for k, v in ep.items() if k in ("R1", "R2", "M1", "M2", "M3")}
    second = {k: v for k, v in moved.items() if k != "M1"}
    model = FieldModel("b", RangeWalkModel(), {})
    grazing = ("grazing: the disc is 24 % of the beam's width",)

    def weak(side, ids):
        return {k: replace(v, flags=grazing) if k in ids else v for k, v in side.items()}

    sharp = corrected_side("e", {1: first, 2: second}, model).join
    assert sharp.joined == (1, 2) and not sharp.weak and not any(code(f) == FLAG_SETUP_JOIN_WEAK for f in sharp.flags())
    shared = sharp.motions[2]["shared"]
    assert len(shared) >= 4
    poor = shared[:len(shared) - 2]  # two left seen well from both sides: too few to carry the join
    join = corrected_side("e", {1: weak(first, poor), 2: weak(second, poor)}, model).join
    assert join.joined == (1, 2) and set(join.weak[2]) == set(poor)
    line = next(f for f in join.flags() if code(f) == FLAG_SETUP_JOIN_WEAK)
    assert "set-up 2" in line and all(t in line for t in poor)
    assert join.to_json()["weak"] == {"2": list(join.weak[2])}
    # three seen well from both: no flag
    ok = corrected_side("e", {1: weak(first, shared[:len(shared) - 3]), 2: weak(second, shared[:len(shared) - 3])},
                        model).join
    assert not ok.weak

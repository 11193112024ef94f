"""Each systematic effect of the simulator against its definition (and off, it draws no random numbers)."""
from dataclasses import replace

import numpy as np
import pytest

from common.errors import InputError
from lidar.angles import spherical_from_xyz, window_around
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.bridge import deck_mesh
from lidar.simulate.effects import (
    ARCSEC,
    AxisErrors,
    DriftModel,
    ExponentialStrengthWalk,
    IntensityModel,
    InverseSquareWalk,
    LinearIncidenceWalk,
    LogisticStrengthWalk,
    StrengthStepWalk,
    VisitTiming,
    return_strength,
    walk_from_dict,
    walk_to_dict,
)
from lidar.simulate.truth import ScanTruth, WindowTruth

SETUP = ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0, pitch_deg=0.03, roll_deg=-0.02)
MODEL = BridgeModel()
WALKS = [LinearIncidenceWalk(), InverseSquareWalk(), StrengthStepWalk(), LogisticStrengthWalk(),
         ExponentialStrengthWalk()]


def window_on(truth_target, half=0.12, step=0.006):
    t, p, _ = spherical_from_xyz(np.array([truth_target.centre_socs_m]))
    return window_around(t[0], p[0], half, half, step, step)


def scan_pair(conditions, target="R2", *, noise=None, **kw):
    """The same window scanned with today's defaults and with ``conditions``, from the same seed."""
    base = BridgeScene(MODEL, EpochConditions(), SETUP)
    w = window_on(base.truth().target(target))
    a, ta = base.scan(w, rng=np.random.default_rng(1), range_noise_m=noise)
    b, tb = BridgeScene(MODEL, conditions, SETUP).scan(w, rng=np.random.default_rng(1), range_noise_m=noise, **kw)
    return a, ta, b, tb


def test_effects_off_draw_no_random_numbers_and_change_nothing():
    on = EpochConditions(range_scale_ppm=25.0, range_walk=InverseSquareWalk(), clipped_fraction=0.2,
                         deck_strain=3e-4, drift=DriftModel(tilt_x_arcsec_per_h=5.0), timing=VisitTiming(start_s=9.0))
    for cond in (EpochConditions(), on):
        r1, r2 = np.random.default_rng(4), np.random.default_rng(4)
        scene = BridgeScene(MODEL, cond, SETUP)
        w = window_on(scene.truth().target("M3"))
        scene.scan(w, rng=r1)
        r2.normal(size=w.n_directions)
        r2.normal(size=w.n_directions)
        assert r1.bit_generator.state == r2.bit_generator.state  # two draws per direction, as before
    a, _, b, tb = scan_pair(EpochConditions(fixed_bearing_x_m=None, range_walk=None, drift=None))
    np.testing.assert_array_equal(a.xyz_socs, b.xyz_socs)
    assert b.time_s is None and tb.windows == () and tb.range_walk is None and tb.drift is None


def test_a_known_ppm_scales_every_range_by_exactly_that():
    ppm = -27.5
    a, _, b, tb = scan_pair(EpochConditions(range_scale_ppm=ppm))
    ra, rb = np.linalg.norm(a.xyz_socs, axis=1), np.linalg.norm(b.xyz_socs, axis=1)
    np.testing.assert_allclose(rb / ra, 1.0 + ppm * 1e-6, rtol=0, atol=1e-13)
    # directions unchanged
    np.testing.assert_allclose(a.xyz_socs / ra[:, None], b.xyz_socs / rb[:, None], atol=1e-13)
    assert tb.range_scale_ppm == ppm
    t = tb.target("R2")
    np.testing.assert_allclose(np.linalg.norm(t.centre_observed_socs_m), t.range_m * (1 + ppm * 1e-6), rtol=1e-14)


def test_range_walk_forms_give_their_documented_bias():
    # head-on at 15 m: strength 1
    assert return_strength(15.0, 1.0) == pytest.approx(1.0)
    assert return_strength(30.0, 0.5, 0.5) == pytest.approx(0.0625)
    r, c = np.array([15.0, 30.0]), np.array([1.0, 0.5])
    s = return_strength(r, c)
    np.testing.assert_allclose(LinearIncidenceWalk(0.0012).bias_m(r, c, s), [0.0012, 0.0006])
    np.testing.assert_allclose(InverseSquareWalk(0.003, 15.0).bias_m(r, c, s), [0.0015, 0.003 * 0.125 / 1.125])
    np.testing.assert_allclose(StrengthStepWalk(0.0012, 0.0002, 0.5).bias_m(r, c, s), [0.0012, 0.0002])
    np.testing.assert_allclose(LogisticStrengthWalk(0.0015, 0.5, 0.15).bias_m(r, c, s),
                               0.0015 / (1 + np.exp(-(s - 0.5) / 0.15)))
    np.testing.assert_allclose(ExponentialStrengthWalk(0.0015, 0.5).bias_m(r, c, s), 0.0015 * (1 - np.exp(-s / 0.5)))
    assert LogisticStrengthWalk().bias_m(15.0, 1.0, 0.5) == pytest.approx(0.00075)
    for w in WALKS:
        assert walk_from_dict(walk_to_dict(w)) == w
        b = w.bias_m(np.array([10.0, 20.0, 40.0]), np.array([1.0, 0.8, 0.3]), np.array([2.25, 0.45, 0.04]))
        assert b.shape == (3,) and np.all(b >= 0) and b[0] >= b[2]  # strong, near, head-on reads shortest
    assert walk_from_dict(None) is None and walk_to_dict(None) is None
    with pytest.raises(InputError, match="unknown range walk"):
        walk_from_dict({"form": "quartic"})


@pytest.mark.parametrize("walk", WALKS, ids=lambda w: w.form)
def test_range_walk_shortens_target_ranges_only(walk):
    a, _, b, tb = scan_pair(EpochConditions(range_walk=walk), noise=0.0)
    ra, rb = np.linalg.norm(a.xyz_socs, axis=1), np.linalg.norm(b.xyz_socs, axis=1)
    on = a.intensity > 0.8  # well inside the disc: full cover
    short = ra - rb
    t = tb.target("R2")
    assert t.range_bias_m == pytest.approx(float(walk.bias_m(t.range_m, t.cos_incidence,
                                                             return_strength(t.range_m, t.cos_incidence))))
    np.testing.assert_allclose(np.median(short[on]), t.range_bias_m, rtol=0.02, atol=2e-6)
    fp = 0.007 + 0.3e-3 * t.range_m
    background = np.linalg.norm(a.xyz_socs - np.asarray(t.centre_socs_m), axis=1) > 0.025 + 2 * fp
    assert np.count_nonzero(background) > 500
    np.testing.assert_array_equal(short[background], 0.0)
    assert tb.range_walk == walk_to_dict(walk)


def test_range_walk_applies_to_cable_tie_returns():
    walk = LinearIncidenceWalk(0.002)
    base = BridgeScene(MODEL, EpochConditions(cable_ties=("R1",)), SETUP)
    w = window_on(base.truth().target("R1"), half=0.2)
    a, _ = base.scan(w, rng=np.random.default_rng(4), range_noise_m=0.0)
    b, _ = BridgeScene(MODEL, EpochConditions(cable_ties=("R1",), range_walk=walk), SETUP).scan(
        w, rng=np.random.default_rng(4), range_noise_m=0.0)
    short = np.linalg.norm(a.xyz_socs, axis=1) - np.linalg.norm(b.xyz_socs, axis=1)
    c = np.asarray(base.truth().target("R1").centre_socs_m)
    tie = (a.intensity > 0.5) & (np.linalg.norm(a.xyz_socs - c, axis=1) > 0.035)
    assert np.count_nonzero(tie) > 10
    assert np.all(short[tie] > 0.001)


def test_clipped_fraction_of_target_points_plateaus_at_the_ceiling():
    a, ta, b, _ = scan_pair(EpochConditions(clipped_fraction=0.4))
    on = a.intensity > 0.45
    assert 0.0 == np.mean(a.intensity_raw[on] == 65535)
    assert np.mean(b.intensity_raw[on] == 65535) == pytest.approx(0.4, abs=0.08)
    np.testing.assert_array_equal(a.intensity_raw[~on], b.intensity_raw[~on])
    clipped = b.intensity_raw == 65535
    # the strongest returns clip: the clipped ones are the nearest the disc's centre (full cover)
    c = np.asarray(ta.target("R2").centre_socs_m)
    assert np.linalg.norm(b.xyz_socs[clipped] - c, axis=1).max() < 0.025
    with pytest.raises(InputError, match="clipped fraction"):
        EpochConditions(clipped_fraction=1.5)


@pytest.mark.parametrize("fixed", [None, 30.0])
def test_deck_strain_moves_deck_targets_along_x_and_not_the_piers(fixed):
    strain = 12e-6 * 25.0
    model = BridgeModel(spans_m=(39.9, 39.9, 39.9))
    setup = ScannerSetup((60.0, -15.0, 1.5), heading_deg=40.0)
    scene = BridgeScene(model, EpochConditions(deck_strain=strain, fixed_bearing_x_m=fixed), setup)
    x_fixed = 0.0 if fixed is None else fixed
    truth = scene.truth()
    assert truth.deck_strain == strain and truth.fixed_bearing_x_m == x_fixed
    for t in truth.targets:
        c0 = np.asarray(model.target(t.id).centre_m)
        moved = np.asarray(t.centre_bridge_m) - c0
        if t.group == "measurement":
            assert t.along_span_m == pytest.approx(strain * (c0[0] - x_fixed), abs=1e-15)
            assert moved[0] == pytest.approx(strain * (c0[0] - x_fixed), abs=1e-12)
        else:
            assert t.along_span_m == 0.0 and np.all(moved == 0.0)
    v0, _ = deck_mesh(model, 0.0)
    v1, _ = deck_mesh(model, 0.0, strain=strain, fixed_x_m=x_fixed)
    np.testing.assert_allclose(v1[:, 0] - v0[:, 0], strain * (v0[:, 0] - x_fixed), atol=1e-12)
    np.testing.assert_array_equal(v1[:, 1:], v0[:, 1:])


def test_deck_strain_shows_in_the_scanned_deck_target():
    strain = 5e-4  # large, so the shift is many times the noise of the centroid
    setup = ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0)
    base = BridgeScene(MODEL, EpochConditions(), setup)
    hot = BridgeScene(MODEL, EpochConditions(deck_strain=strain), setup)
    m5 = hot.truth().target("M5")
    w = window_on(base.truth().target("M5"), half=0.15, step=0.004)
    b, _ = hot.scan(w, rng=np.random.default_rng(2), range_noise_m=0.0)
    pts = b.xyz_socs[b.intensity > 0.8] @ setup.rotation.T + np.asarray(setup.position_m)
    assert pts[:, 0].mean() - MODEL.target("M5").centre_m[0] == pytest.approx(strain * 32.0, abs=0.002)
    assert m5.along_span_m == pytest.approx(strain * 32.0)


def test_drift_rotates_a_late_window_by_rate_times_time_about_the_scanner_origin():
    drift = DriftModel(tilt_x_arcsec_per_h=30.0, tilt_y_arcsec_per_h=-20.0, twist_arcsec_per_h=40.0)
    start, late = 500.0, 500.0 + 2 * 3600.0
    cond = EpochConditions(drift=drift, timing=VisitTiming(start_s=start))
    a, ta, b, tb = scan_pair(cond, noise=0.0, start_s=late)
    angles = drift.angles_rad(late - start)[0]
    np.testing.assert_allclose(np.degrees(angles) * 3600, [60.0, -40.0, 80.0])
    r2 = ta.target("R2")
    c, n = np.asarray(r2.centre_socs_m), np.asarray(r2.normal_socs)
    on = b.intensity > 0.45
    back = drift.to_start(b.xyz_socs[on], b.time_s[on] - start)
    assert np.abs((back - c) @ n).max() < 1e-9  # rotated back, the points lie on the disc again
    assert np.abs((b.xyz_socs[on] - c) @ n).max() > 1e-3
    # the centroid moved by the rotation about the scanner origin (not about the target)
    ca, cb = a.xyz_socs[a.intensity > 0.45].mean(axis=0), b.xyz_socs[on].mean(axis=0)
    from scipy.spatial.transform import Rotation
    want = Rotation.from_rotvec(angles).inv().apply(ca)
    assert np.linalg.norm(cb - want) < 4e-4 < 0.1 * np.linalg.norm(cb - ca)
    np.testing.assert_allclose(tb.target("R2").centre_observed_socs_m,
                               Rotation.from_rotvec(drift.angles_rad(tb.target("R2").time_s - start)[0]).inv()
                               .apply(c), atol=1e-12)
    assert tb.drift == drift.to_dict()


def test_drift_round_trip_and_quadratic_term():
    d = DriftModel(tilt_x_arcsec_per_h=1.0, twist_arcsec_per_h2=4.0)
    assert DriftModel.from_dict(d.to_dict()) == d
    a = np.degrees(d.angles_rad([0.0, 1800.0, 3600.0])) * 3600
    np.testing.assert_allclose(a, [[0, 0, 0], [0.5, 0, 1.0], [1.0, 0, 4.0]], atol=1e-12)
    v = np.random.default_rng(0).normal(size=(5, 3))
    np.testing.assert_allclose(d.to_current(d.to_start(v, 7200.0), 7200.0), v, atol=1e-14)


@pytest.mark.parametrize("duration", ["points", "lines"])
def test_times_are_monotonic_and_span_the_window(duration):
    timing = VisitTiming(start_s=1000.0, rate_hz=50_000.0, duration=duration)
    scene = BridgeScene(MODEL, EpochConditions(timing=timing), SETUP)
    w = window_on(scene.truth().target("M2"))
    scan, truth = scene.scan(w, rng=np.random.default_rng(0), start_s=1234.5)
    assert np.all(np.diff(scan.time_s) > 0)
    (span,) = truth.windows
    assert span.start_s == 1234.5
    if duration == "points":
        assert span.end_s == pytest.approx(1234.5 + w.n_directions / 50_000.0)
    else:
        rows, cols = w.shape
        line = max(100.0 / w.theta_step_deg / 50_000.0, 1 / 120.0)
        assert span.end_s == pytest.approx(1234.5 + cols * line)
    assert span.start_s <= scan.time_s.min() and scan.time_s.max() < span.end_s
    assert span.start_s < truth.target("M2").time_s < span.end_s


def test_truth_version_2_round_trips_and_version_1_loads(tmp_path):
    cond = EpochConditions(range_walk=StrengthStepWalk(), range_scale_ppm=12.0, drift=DriftModel(1.0, 2.0, 3.0),
                           deck_strain=1e-4)
    scene = BridgeScene(MODEL, cond, SETUP)
    _, truth = scene.scan(window_on(scene.truth().target("R2")), rng=np.random.default_rng(0))
    back = ScanTruth.load(truth.save(tmp_path / "t.json"))
    assert back.to_dict() == truth.to_dict()
    assert back.windows == truth.windows and back.target("R2").centre_observed_socs_m is not None
    v1 = {"format_version": 1, "scanner_pose": np.eye(4).tolist(), "midspan_displacement_m": -0.002,
          "removed": [], "range_noise_m": 0.005,
          "targets": [{"id": "R1", "group": "reference", "centre_bridge_m": [1, 2, 3], "centre_socs_m": [4, 5, 6],
                       "normal_socs": [1, 0, 0], "vertical_displacement_m": 0.0, "moved": False, "occluded": False,
                       "cable_tie": False, "points_on_target": 12}]}
    old = ScanTruth.from_dict(v1)
    assert old.target("R1").points_on_target == 12 and old.target("R1").range_bias_m == 0.0
    assert old.range_walk is None and old.windows == () and old.range_scale_ppm == 0.0


def test_axis_errors_shift_the_angles_as_a_theodolite_s_and_invert():
    """Collimation c / sin(theta) and trunnion i cot(theta) in azimuth, the vertical index in zenith."""
    ax = AxisErrors(collimation_arcsec=12.0, trunnion_arcsec=-30.0, vertical_index_arcsec=7.0)
    theta = np.radians([90.0, 60.0, 30.0, 120.0])
    phi = np.radians([0.0, 45.0, 200.0, 300.0])
    rep = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    beam = ax.beam_directions(rep)
    t_b = np.arctan2(np.hypot(beam[:, 0], beam[:, 1]), beam[:, 2])
    p_b = np.arctan2(beam[:, 1], beam[:, 0])
    np.testing.assert_allclose((t_b - theta) / ARCSEC, 7.0, atol=1e-6)
    want = 12.0 / np.sin(theta) - 30.0 * np.cos(theta) / np.sin(theta)
    np.testing.assert_allclose(np.angle(np.exp(1j * (p_b - phi))) / ARCSEC, want, atol=1e-6)
    np.testing.assert_allclose(ax.reported_directions(beam), rep, atol=1e-12)
    assert AxisErrors.from_dict(ax.to_dict()) == ax and AxisErrors.from_dict(None) is None
    with pytest.raises(InputError):
        AxisErrors(collimation_arcsec=float("nan"))


def test_a_scale_changing_during_the_visit_scales_each_point_by_its_own_time():
    ppm, rate = 10.0, -36.0  # -36 ppm an hour: -0.01 ppm a second
    timing = VisitTiming(start_s=500.0)
    a, _, b, tb = scan_pair(EpochConditions(range_scale_ppm=ppm, range_scale_rate_ppm_h=rate, timing=timing),
                            noise=0.0, start_s=2300.0)
    assert b.time_s is not None and b.time_s.min() >= 2300.0
    ra, rb = np.linalg.norm(a.xyz_socs, axis=1), np.linalg.norm(b.xyz_socs, axis=1)
    expected = 1.0 + (ppm + rate * (b.time_s - 500.0) / 3600.0) * 1e-6  # -8 ppm and less, 1800 s in
    np.testing.assert_allclose(rb / ra, expected, rtol=0, atol=1e-13)
    t = tb.target("R2")
    scale = ppm + rate * (t.time_s - 500.0) / 3600.0
    np.testing.assert_allclose(np.linalg.norm(t.centre_observed_socs_m), t.range_m * (1 + scale * 1e-6), rtol=1e-14)
    assert EpochConditions(range_scale_rate_ppm_h=1.0).timed
    with pytest.raises(InputError):
        EpochConditions(range_scale_rate_ppm_h=float("nan"))


def test_the_truth_of_a_scale_changing_during_the_visit_is_its_value_over_the_target_windows(tmp_path):
    """What one scale fitted to a visit measures: the scale over its target scans, not at the visit's start."""
    timing = VisitTiming(start_s=500.0)
    scene = BridgeScene(MODEL, EpochConditions(range_scale_ppm=10.0, range_scale_rate_ppm_h=-36.0, timing=timing),
                        SETUP)
    _, truth = scene.scan(window_on(scene.truth().target("R2")), rng=np.random.default_rng(0), start_s=2300.0)
    (w,) = truth.windows
    assert truth.range_scale_rate_ppm_h == -36.0
    # -0.01 ppm a second from 500 s: at the window's middle, 1800 s and more later, -8 ppm and less
    assert truth.range_scale_during_ppm() == pytest.approx(10.0 - 0.01 * (0.5 * (w.start_s + w.end_s) - 500.0))
    back = ScanTruth.load(truth.save(tmp_path / "t.json"))
    assert back.range_scale_during_ppm() == truth.range_scale_during_ppm() < -8.0
    coarse = replace(truth, windows=(WindowTruth("coarse", 500.0, 560.0), w))  # the coarse scan is no target's
    assert coarse.range_scale_during_ppm() == truth.range_scale_during_ppm()
    steady = BridgeScene(MODEL, EpochConditions(range_scale_ppm=10.0, timing=timing), SETUP)
    assert steady.scan(window_on(steady.truth().target("R2")), rng=np.random.default_rng(0),
                       start_s=2300.0)[1].range_scale_during_ppm() == 10.0


def test_a_scan_with_axis_errors_reports_the_target_where_the_truth_says():
    """The disc's points are found where the beams really went, and reported along the directions read."""
    ax = AxisErrors(collimation_arcsec=40.0, trunnion_arcsec=40.0, vertical_index_arcsec=-60.0, range_offset_m=0.004)
    a, ta, b, tb = scan_pair(EpochConditions(axis_errors=ax), noise=0.0)
    t = tb.target("R2")
    observed, true = np.asarray(t.centre_observed_socs_m), np.asarray(t.centre_socs_m)
    assert np.linalg.norm(observed) - np.linalg.norm(true) == pytest.approx(0.004, abs=1e-9)
    assert np.linalg.norm(observed - true) > 0.004  # the angles moved it too
    bright_a, bright_b = a.xyz_socs[a.intensity > 0.6], b.xyz_socs[b.intensity > 0.6]
    shift = bright_b.mean(axis=0) - bright_a.mean(axis=0)  # the disc seen through the errors, less the clean one
    np.testing.assert_allclose(shift, observed - true, atol=0.6e-3)
    assert tb.axis_errors == ax.to_dict() and ScanTruth.from_dict(tb.to_dict()).axis_errors == ax.to_dict()


def test_a_walk_factor_scales_one_targets_walk_only():
    walk = LinearIncidenceWalk(0.0015)
    a, _, b, tb = scan_pair(EpochConditions(range_walk=walk), noise=0.0)
    _, _, c, tc = scan_pair(EpochConditions(range_walk=walk, walk_factors={"R2": 1.8, "M1": 0.0}), noise=0.0)
    assert tc.target("R2").range_bias_m == pytest.approx(1.8 * tb.target("R2").range_bias_m)
    assert tc.target("M1").range_bias_m == 0.0
    on = a.intensity > 0.6  # R2's points: each reads 1.8 times as short as under the campaign's walk
    ra, rb, rc = (np.linalg.norm(s.xyz_socs[on], axis=1) for s in (a, b, c))
    assert (ra - rb).min() > 1e-4
    np.testing.assert_allclose(ra - rc, 1.8 * (ra - rb), rtol=1e-9, atol=1e-12)
    with pytest.raises(InputError):
        EpochConditions(walk_factors={"R2": -1.0})


def test_a_drift_can_jump_once_during_the_visit():
    d = DriftModel(tilt_x_arcsec_per_h=3.6, jump_x_arcsec=20.0, jump_z_arcsec=-10.0, jump_after_s=900.0)
    a = np.degrees(d.angles_rad([0.0, 899.0, 901.0, 3600.0])) * 3600
    np.testing.assert_allclose(a, [[0, 0, 0], [0.899, 0, 0], [20.901, 0, -10.0], [23.6, 0, -10.0]], atol=1e-9)
    assert DriftModel.from_dict(d.to_dict()) == d
    steady = DriftModel(2.0)
    assert steady.to_dict()["jump_after_s"] is None and DriftModel.from_dict(steady.to_dict()) == steady
    with pytest.raises(InputError):
        DriftModel(jump_after_s=float("nan"))


def test_intensity_models_follow_their_formulas():
    value, rng_m, z = np.array([0.24, 0.24, 0.24, 23.0]), np.array([8.0, 16.0, 32.0, 40.0]), np.zeros(4)
    mild = IntensityModel().report(value, rng_m, z)
    np.testing.assert_allclose(mild, np.clip(value * np.clip(1 - 0.004 * rng_m, 0.6, 1.0), 0.0, 1.0))
    amp = IntensityModel("amplitude", reference_range_m=16.0)
    a = amp.report(value, rng_m, z)
    np.testing.assert_allclose(a[1:3], [0.24, 0.06])  # 1/r^2: twice as far, a quarter
    assert a[0] == pytest.approx(0.96) and a[3] == 1.0  # close concrete near the ceiling, the target at it
    db = IntensityModel("db", reference_range_m=16.0, floor_db=-30.0).report(value, rng_m, z)
    np.testing.assert_allclose(db[1:3], (10 * np.log10([0.24, 0.06]) + 30) / 30)
    assert db[3] == 1.0
    speckled = amp.amplitude(value, rng_m, np.full(4, 2.0))
    np.testing.assert_allclose(speckled, amp.amplitude(value, rng_m) * (1 + 2 * amp.speckle))
    np.testing.assert_allclose(amp.surface(0.2, [1.0, 0.5]), [0.2, 0.1])  # Lambert: cos(incidence)
    np.testing.assert_allclose(amp.retro(0.9, 0.5), 0.9 * amp.retro_gain * 0.5)
    with pytest.raises(InputError):
        IntensityModel("linear")
    with pytest.raises(InputError):
        IntensityModel("db", floor_db=3.0)
    assert IntensityModel.from_dict(IntensityModel("db", retro_gain=9.0).to_dict()) == IntensityModel("db", retro_gain=9.0)


def test_the_mild_model_given_scans_as_none_and_every_model_draws_two_numbers_per_direction():
    a, _, b, _ = scan_pair(EpochConditions(intensity_model=IntensityModel()), target="M3")
    np.testing.assert_array_equal(a.intensity_raw, b.intensity_raw)
    np.testing.assert_array_equal(a.xyz_socs, b.xyz_socs)
    for kind in ("amplitude", "db"):
        r1, r2 = np.random.default_rng(4), np.random.default_rng(4)
        scene = BridgeScene(MODEL, EpochConditions(intensity_model=IntensityModel(kind)), SETUP)
        w = window_on(scene.truth().target("M3"))
        scene.scan(w, rng=r1)
        r2.normal(size=w.n_directions)
        r2.normal(size=w.n_directions)
        assert r1.bit_generator.state == r2.bit_generator.state


def test_amplitude_clips_targets_and_its_db_scale_is_the_log_of_the_same_returns():
    """Under the amplitude model a target reads the ceiling; the dB model reports the same returns' logarithm."""
    scans = {}
    for kind in ("amplitude", "db"):
        scene = BridgeScene(MODEL, EpochConditions(intensity_model=IntensityModel(kind)), SETUP)
        truth = scene.truth()
        w = window_on(truth.target("M3"), half=0.6, step=0.02)
        scans[kind], _ = scene.scan(w, rng=np.random.default_rng(8))
    amp, db = scans["amplitude"], scans["db"]
    np.testing.assert_array_equal(amp.xyz_socs, db.xyz_socs)  # the same rays and ranges
    centre = np.asarray(truth.target("M3").centre_socs_m)
    on_disc = np.linalg.norm(amp.xyz_socs - centre, axis=1) < 0.015
    assert on_disc.sum() > 5 and np.all(amp.intensity[on_disc] == 1.0) and np.all(db.intensity[on_disc] == 1.0)
    surface = (amp.intensity > 0.02) & (amp.intensity < 0.99)
    assert surface.sum() > 1000
    np.testing.assert_allclose(db.intensity[surface], (10 * np.log10(amp.intensity[surface]) + 30) / 30, atol=2e-3)
    # the deck around the target: well below the ceiling, and its amplitude falls with range as 1/r^2 x cos
    assert np.median(amp.intensity[surface]) < 0.5

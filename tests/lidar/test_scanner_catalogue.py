"""The scanner catalogue and what planning makes of each instrument."""
import json
import math

import numpy as np
import pytest

from common.errors import InputError
from lidar.plan import PlanTarget, ScanPlan, plan_fine_scans
from lidar.scanner_catalogue import CATALOGUE, get_scanner
from lidar.scanner_profile import ScannerProfile, load_profile

REQUIRED = {"Riegl VZ-400i", "Riegl VZ-1000", "Riegl VZ-2000i", "Leica ScanStation P50", "Leica RTC360",
            "Trimble X7", "Trimble TX8", "FARO Focus Premium", "Z+F IMAGER 5016"}
SOURCED = ("pulse_rate_hz", "range_noise_m", "theta_fov_deg", "beam_divergence_mrad", "beam_exit_diameter_m",
           "windowed", "angles", "window_overhead_s")


def _targets():
    """A pier target at 25 m and a deck target at 12 m seen from below, as a planner gets them."""
    return [PlanTarget("R1", "reference", (25.0, 0.0, 2.0), 0.05, False, 0.8),
            PlanTarget("M1", "measurement", (4.0, 2.0, 9.0), 0.05, False, 0.9),
            PlanTarget("M2", "measurement", (-6.0, 3.0, 8.0), 0.05, False, 0.6)]


def test_catalogue_holds_the_monitoring_scanners_with_sources():
    assert REQUIRED <= set(CATALOGUE)
    for name, prof in CATALOGUE.items():
        src = dict(prof.sources)
        missing = [f for f in SOURCED if not src.get(f)]
        assert not missing, f"{name}: no source for {missing}"
        if prof.step_presets:
            assert src.get("step_presets"), name
        else:
            assert src.get("min_theta_step_deg") and src.get("min_phi_step_deg"), name


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_plans_use_only_what_the_instrument_offers(name):
    prof = CATALOGUE[name]
    plan = plan_fine_scans(_targets(), profile=prof, min_points=1000, budget_seconds=7200)
    steps = {lab: st for lab, st in prof.step_presets}
    for roi in plan.rois:
        w = roi.window
        if prof.step_presets:
            assert w.theta_step_deg == w.phi_step_deg
            assert any(abs(w.theta_step_deg - s) < 1e-12 for s in steps.values())
            assert plan.instrument_window(roi)["resolution"].split(", quality")[0] in steps
        else:
            assert w.theta_step_deg >= prof.min_theta_step_deg - 1e-12
            assert w.phi_step_deg >= prof.min_phi_step_deg - 1e-12
    if prof.windowed:
        assert plan.dome_seconds == 0 and all(r.expected_seconds > 0 for r in plan.rois)
    else:  # one full dome, every window cut from it
        assert plan.dome_seconds > 0 and all(r.expected_seconds == 0 for r in plan.rois)
        assert math.isclose(plan.total_seconds, plan.dome_seconds)
        assert plan.rois[0].window.theta_step_deg == plan.dome_step_deg
    d = plan.to_json()
    for key in ("epoch", "scanner_profile", "total_seconds", "rois"):
        assert key in d
    back = ScanPlan.from_json(json.loads(json.dumps(d)))
    assert back.profile == prof and math.isclose(back.total_seconds, plan.total_seconds, abs_tol=0.1)


def test_preset_scanner_gets_the_coarsest_preset_that_still_gives_the_points():
    prof = CATALOGUE["Leica ScanStation P50"]
    plan = plan_fine_scans(_targets(), profile=prof, min_points=1000, budget_seconds=7200)
    presets = [s for _, s in prof.step_presets]
    for roi in plan.rois:
        if roi.window.theta_step_deg > min(presets):  # (the finest preset gives what it can)
            assert roi.expected_target_points >= 1000
        else:
            assert "finest steps give only" in " ".join(roi.notes) or roi.expected_target_points >= 1000
        coarser = [s for s in presets if s > roi.window.theta_step_deg]
        if coarser:  # the next coarser preset would not give the points
            r2 = roi.expected_target_points * (roi.window.theta_step_deg / min(coarser)) ** 2
            assert r2 < 1000


def test_full_dome_scanner_drops_to_a_preset_that_fits_the_budget():
    prof = CATALOGUE["Leica RTC360"]
    fine = plan_fine_scans(_targets(), profile=prof, min_points=20000, budget_seconds=7200)
    tight = plan_fine_scans(_targets(), profile=prof, min_points=20000, budget_seconds=150)
    assert tight.dome_step_deg > fine.dome_step_deg
    assert tight.total_seconds <= 150
    assert any("budget" in w for w in tight.warnings)


def test_instrument_angles_follow_each_convention():
    riegl = CATALOGUE["Riegl VZ-1000"]
    hz, v = riegl.instrument_angles(80.0, 30.0)
    assert (float(hz), float(v)) == (30.0, 80.0)
    leica = CATALOGUE["Leica ScanStation P50"]  # clockwise from the y axis, zenith angle
    hz, v = leica.instrument_angles(80.0, 30.0)
    assert math.isclose(float(hz), 60.0) and float(v) == 80.0
    hz, v = leica.instrument_angles(80.0, 120.0)
    assert math.isclose(float(hz), 330.0)
    faro = CATALOGUE["FARO Focus Premium"]  # elevation
    assert math.isclose(float(faro.instrument_angles(80.0, 30.0)[1]), 10.0)


def test_instrument_window_is_ordered_in_instrument_terms():
    prof = CATALOGUE["Trimble TX8"]
    plan = plan_fine_scans(_targets(), profile=prof, min_points=500, budget_seconds=7200)
    for roi in plan.rois:
        iw = plan.instrument_window(roi)
        assert iw["v_start_deg"] < iw["v_end_deg"]
        width = (iw["h_end_deg"] - iw["h_start_deg"]) % 360
        assert math.isclose(width, roi.window.phi_max_deg - roi.window.phi_min_deg, abs_tol=1e-3)


def test_get_scanner_by_name_or_file(tmp_path):
    assert get_scanner("vz-1000").name == "Riegl VZ-1000"
    assert get_scanner("Z+F IMAGER 5016").name == "Z+F IMAGER 5016"
    with pytest.raises(InputError, match="unknown scanner 'Leica Nova'.*Riegl VZ-1000"):
        get_scanner("Leica Nova")
    own = dict(CATALOGUE["Leica RTC360"].to_dict(), name="Our RTC360 (windows firmware)", windowed=True)
    f = tmp_path / "rtc.json"
    f.write_text(json.dumps(own))
    prof = get_scanner(str(f))
    assert prof.name == "Our RTC360 (windows firmware)" and prof.windowed
    assert load_profile(f) == prof


@pytest.mark.parametrize("text, message", [
    ("{", "not a JSON scanner profile"),
    ('{"pulse_rate_hz": 1000}', "needs a 'name'"),
    ('{"name": "x", "pulse_rate_hz": -5}', "pulse_rate_hz must be a positive number"),
    ('{"name": "x", "pulse_rate_hz": NaN}', "pulse_rate_hz must be a positive number"),
    ('{"name": "x", "kind": "spinning"}', "kind must be one of"),
    ('{"name": "x", "windowed": false}', "full-dome-only scanner needs step_presets"),
    ('{"name": "x", "step_presets": [{"label": "a"}]}', "malformed scanner profile"),
])
def test_bad_profile_files_are_refused_in_one_line(tmp_path, text, message):
    f = tmp_path / "p.json"
    f.write_text(text)
    with pytest.raises(InputError, match=message) as err:
        load_profile(f)
    assert str(f) in str(err.value) and "\n" not in str(err.value)


def test_old_stored_profiles_still_load():
    old = {"name": "Riegl VZ-1000", "pulse_rate_hz": 122000.0, "range_noise_m": 0.005, "min_theta_step_deg": 0.001,
           "min_phi_step_deg": 0.006, "theta_fov_deg": [30.0, 130.0], "max_line_rate_hz": 120.0,
           "window_overhead_s": 3.0, "beam_divergence_mrad": 0.3, "beam_exit_diameter_m": 0.007,
           "max_range_m": 1400.0}
    prof = ScannerProfile.from_dict(old)
    assert prof.windowed and prof.kind == "line" and prof.window_overhead_s == 3.0
    assert np.isclose(prof.line_seconds(0.01), 100 / 0.01 / 122000.0)

"""The application's logic that needs no Qt: imported and used without PySide6."""
import subprocess
import sys

from app.gui.state.map_geometry import CellRect, window_from_cells, window_of_cells


def qt_free_modules() -> list[str]:
    """app.gui.actions and every module of app.gui.state."""
    import pkgutil

    import app.gui.state

    return ["app.gui.actions"] + [f"app.gui.state.{m.name}" for m in pkgutil.iter_modules(app.gui.state.__path__)]


def test_these_modules_do_not_import_qt():
    mods = qt_free_modules()
    assert "app.gui.state.app_state" in mods and "app.gui.state.status" in mods
    code = ("import sys, importlib\n"
            f"for m in {mods!r}: importlib.import_module(m)\n"
            "print([m for m in sys.modules if m.startswith(('PySide6', 'shiboken6', 'pyvistaqt', 'qtpy', 'vtk'))])")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_window_of_cells_keeps_the_plan_contract_across_zero():
    w = window_of_cells(CellRect(left=45, top=10, width=10, height=4), 60.0, 355.0, 0.1)
    assert w["phi_min_deg"] < w["phi_max_deg"] and w["phi_min_deg"] < 0 < w["phi_max_deg"]
    assert (w["theta_min_deg"], w["theta_max_deg"]) == (61.0, 61.4)


def test_window_from_cells_and_the_details_html_on_a_campaign(processed_copy):
    from app.gui.state.details_html import campaign_html, epoch_html, reflector_html
    from projects.results.status import campaign_status
    from projects.store.campaign import Campaign

    with Campaign.open(processed_copy, writable=False) as c:
        preview = c.map_preview("2026-03-02")
        plan = c.plan("2026-03-02")
        refl = c.reflector("M3")
        html_c = campaign_html(c, campaign_status(c))
        html_e = epoch_html(c, "2026-03-02")
        html_r = reflector_html(c, "M3")
    roi = plan.roi("M3")
    g = preview.reflectance_map
    t0 = (roi.window.theta_min_deg - g.theta0_deg) / g.step_deg
    p0 = ((roi.window.phi_min_deg - g.phi0_deg) % 360.0) / g.step_deg
    rect = CellRect(p0, t0, (roi.window.phi_max_deg - roi.window.phi_min_deg) / g.step_deg,
                    (roi.window.theta_max_deg - roi.window.theta_min_deg) / g.step_deg)
    new = window_from_cells(preview, plan, rect, "M3", refl)
    assert abs(new.range_m - roi.range_m) < 0.5
    assert abs(new.window.phi_min_deg - roi.window.phi_min_deg) < 1e-4
    assert new.expected_target_points > 0.5 * plan.min_points
    assert "Test bridge" in html_c and "2026-03-02" in html_e and "M3" in html_r
    assert "<b>Instrument</b>" in html_c and "range walk: " in html_c and "axis errors: " in html_c
    assert "Corrected for" in html_e and "scale 0 ppm (the baseline defines it)" in html_e


def test_the_docstring_examples_of_the_state_run():
    import doctest
    import importlib

    for name in qt_free_modules():
        result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
        assert result.failed == 0, name

"""The plan editor behind the map view: edits, drags as one step, undo, redo, revert, saved state."""
import pytest

from app.gui.state.plan_edit import UNDO_DEPTH, PlanEditor
from lidar.plan import AngularWindow, RoiPlan, ScanPlan
from lidar.scanner_catalogue import DEFAULT_SCANNER, get_scanner


def _plan(n=3):
    rois = tuple(RoiPlan(f"M{k}", "measurement", AngularWindow(60.0 + k, 60.4 + k, 80.0, 80.3, 0.01, 0.01),
                         20.0, 10.0, 1200, 1000, 50.0) for k in range(1, n + 1))
    return ScanPlan("e1", get_scanner(DEFAULT_SCANNER), rois, 1000, 1000, 3600.0)


def _win(roi, d_phi=0.0, widen=0.0):
    w = roi.window
    return {"phi_min_deg": w.phi_min_deg + d_phi, "phi_max_deg": w.phi_max_deg + d_phi + widen,
            "theta_min_deg": w.theta_min_deg, "theta_max_deg": w.theta_max_deg}


def test_a_drag_is_one_undo_step_and_seconds_follow_the_shape():
    calls = []
    ed = PlanEditor(_plan(), on_change=lambda: calls.append(1))
    m1 = ed.roi("M1")
    for k in range(1, 6):  # the mouse moves ...
        ed.reshape("M1", _win(m1, d_phi=0.02 * k), final=False)
    assert ed.roi("M1").window.phi_min_deg == pytest.approx(m1.window.phi_min_deg + 0.1)
    assert not ed.can_undo  # ... nothing committed yet
    ed.reshape("M1", _win(m1, d_phi=0.1, widen=0.2), final=True)  # ... and is released
    wide = ed.roi("M1")
    assert wide.expected_points > m1.expected_points and wide.expected_seconds > m1.expected_seconds
    assert wide.expected_target_points == m1.expected_target_points  # the steps stay
    assert ed.dirty and ed.plan.total_seconds > ed.stored.total_seconds and len(calls) >= 7
    assert ed.undo() and ed.roi("M1") == m1 and not ed.dirty  # one undo: back where the drag started
    assert ed.redo() and ed.roi("M1") == wide
    assert not ed.redo()


def test_click_without_moving_changes_nothing_and_bad_shapes_keep_the_last_valid_one():
    ed = PlanEditor(_plan())
    m2 = ed.roi("M2")
    assert ed.reshape("M2", _win(m2), final=True) is m2
    assert not ed.dirty and not ed.can_undo
    off_sky = {**_win(m2), "theta_min_deg": 179.9, "theta_max_deg": 180.5}
    assert ed.reshape("M2", off_sky, final=True) is None
    assert ed.roi("M2") == m2 and not ed.can_undo
    assert ed.reshape("nobody", _win(m2)) is None


def test_add_remove_revert_and_saved_state():
    ed = PlanEditor(_plan())
    m3 = ed.roi("M3")
    assert ed.remove(["M3", "M1"]) and [r.reflector for r in ed.rois] == ["M2"]
    assert not ed.remove(["M3"])  # nothing left to remove
    ed.add(m3)
    assert [r.reflector for r in ed.rois] == ["M2", "M3"] and ed.plan.roi("M3") == m3
    ed.revert()
    assert [r.reflector for r in ed.rois] == ["M1", "M2", "M3"] and not ed.dirty
    assert ed.undo() and [r.reflector for r in ed.rois] == ["M2", "M3"]  # revert itself can be undone
    ed.mark_saved()
    assert not ed.dirty and ed.can_undo
    ed.load(None)
    assert ed.plan is None and ed.rois == () and not ed.can_undo


def test_undo_history_is_bounded():
    ed = PlanEditor(_plan(1))
    m1 = ed.roi("M1")
    for k in range(UNDO_DEPTH + 20):
        ed.reshape("M1", _win(m1, d_phi=0.001 * (k + 1)), final=True)
    n = 0
    while ed.undo():
        n += 1
    assert n == UNDO_DEPTH

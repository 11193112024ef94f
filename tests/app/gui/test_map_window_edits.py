"""Map editing that cannot lose a target by accident (issue 41 item 1): a small window is moved by its body, never
shrunk below its target's disc and margin, and a plan whose window cuts its target says so before it is saved."""
from __future__ import annotations

import pytest
from PySide6.QtCore import QPointF

from lidar.plan import holds
from projects.store.campaign import Campaign
from tests.app.gui.conftest import wait_job
from tests.app.gui.helpers import drag

pytestmark = pytest.mark.gui


def _map_at(window, processed_copy, qtbot, label="2026-03-09"):
    window.open_campaign(processed_copy)
    window.tree.select_key("epoch", label)
    window.tabs.setCurrentWidget(window.map_view)
    qtbot.wait(20)
    return window.map_view


def test_a_small_window_moves_by_its_body_and_never_shrinks_below_its_target(window, processed_copy, qtbot):
    mv = _map_at(window, processed_copy, qtbot)
    item = next(it for it in mv.items if it.roi.reflector == "M3")
    ext = mv.state.extent("M3")
    assert ext is not None and holds(item.roi.window, ext) and item.keep is not None
    zoom = 7.0 / item.scene_rect().width()  # as reported: the window 7 px wide on the screen
    mv.view.resetTransform()
    mv.view.scale(zoom, zoom)
    mv.view.centerOn(item)
    qtbot.wait(20)
    before = item.roi.window
    r = item.scene_rect()
    drag(mv.view, r.center(), r.center() + QPointF(24 / zoom, 16 / zoom))  # its body by (24, 16) px
    after = item.roi.window
    width = lambda w: (w.phi_max_deg - w.phi_min_deg, w.theta_max_deg - w.theta_min_deg)  # noqa: E731
    assert width(after) == pytest.approx(width(before))  # moved, not shrunk
    assert after.theta_min_deg > before.theta_min_deg and holds(after, ext)  # as far as the target lets it
    # a close look: a corner dragged across the whole window stops at the disc and its margin
    zoom = 150.0 / item.scene_rect().width()
    mv.view.resetTransform()
    mv.view.scale(zoom, zoom)
    mv.view.centerOn(item)
    qtbot.wait(20)
    r = item.scene_rect()
    corner = r.bottomRight() - QPointF(1 / zoom, 1 / zoom)
    drag(mv.view, corner, r.topLeft())
    w = item.roi.window
    assert holds(w, ext) and width(w)[0] < width(after)[0] and width(w)[1] < width(after)[1]
    assert w.phi_min_deg == pytest.approx(ext.phi_min_deg, abs=0.01)  # the scene's right edge: phi_min
    assert w.theta_max_deg == pytest.approx(ext.theta_max_deg, abs=0.01)


def test_a_window_that_cuts_its_target_is_said_before_saving(window, processed_copy, qtbot, monkeypatch):
    from PySide6.QtWidgets import QMessageBox

    mv = _map_at(window, processed_copy, qtbot)
    ext = mv.state.extent("M3")
    w = next(it for it in mv.items if it.roi.reflector == "M3").roi.window
    half = (ext.phi_max_deg - ext.phi_min_deg) / 2
    # a window reshaped elsewhere (the editor, as a plan from another tool would be) off half the disc
    mv.editor.reshape("M3", {"phi_min_deg": ext.phi_min_deg + half, "phi_max_deg": w.phi_max_deg + half,
                             "theta_min_deg": w.theta_min_deg, "theta_max_deg": w.theta_max_deg})
    row = [mv.table.item(k, 0).text() for k in range(mv.table.rowCount())].index("M3")
    assert mv.table.item(row, 5).text().startswith("< ") and "cuts the target" in mv.table.item(row, 7).text()
    asked = []
    monkeypatch.setattr(QMessageBox, "question", staticmethod(lambda p, t, text, *a, **k: asked.append(text)
                                                              or QMessageBox.No))
    with Campaign.open(processed_copy, writable=False) as c:
        saved = c.stored_plan("2026-03-09").plan_json
    mv.save_btn.click()
    wait_job(qtbot, window)
    assert len(asked) == 1 and asked[0].startswith("These windows do not hold their whole target: M3 (planned ")
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.stored_plan("2026-03-09").plan_json == saved  # nothing saved
    assert "plan not saved" in window.statusBar().currentMessage()

"""The check is binding in the application (issue 41 item 2): after a check that asks for a re-scan the toolbar's
next step is the re-scan, and Process asks first."""
from __future__ import annotations

import pytest

from projects.store.campaign import Campaign
from tests.app.gui.conftest import wait_job
from tests.projects.campaign_helpers import snapshot
from tests.projects.onsite.test_onsite_check import LABEL, short_visit  # noqa: F401  (fixture)

pytestmark = pytest.mark.gui


def test_the_rescan_comes_next_and_process_asks(window, short_visit, qtbot, monkeypatch):  # noqa: F811
    from PySide6.QtWidgets import QMessageBox

    camp, _ = short_visit
    assert window.open_campaign(camp)
    window.state.select(epoch=LABEL)
    monkeypatch.setattr("app.gui.commands.CheckDialog.show", lambda self: None)
    window.commands.check_selected()
    wait_job(qtbot, window)
    assert window.act_next.text() == f"Next: re-scan M2, M3 of {LABEL}"
    asked = []

    def answer(reply):
        def question(parent, title, text, *a, **k):
            asked.append(text)
            return reply
        return staticmethod(question)

    monkeypatch.setattr(QMessageBox, "question", answer(QMessageBox.No))
    before = snapshot(camp)
    window.commands.process()
    wait_job(qtbot, window)
    assert len(asked) == 1 and f"{LABEL}: re-scan M2 (" in asked[0] and "M3 (not found)" in asked[0]
    assert snapshot(camp) == before and "the re-scan first" in window.statusBar().currentMessage()
    monkeypatch.setattr(QMessageBox, "question", answer(QMessageBox.Yes))
    window.commands.process()
    wait_job(qtbot, window)
    with Campaign.open(camp, writable=False) as c:
        assert c.check_verdict(LABEL).accepted and c.displacement_set(LABEL) is not None
    assert not window.act_next.text().startswith("Next: re-scan")

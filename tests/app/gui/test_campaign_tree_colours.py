"""The campaign tree colours a visit only when it needs action (issue 38.3)."""
from __future__ import annotations

import pytest

pytest.importorskip("PySide6")


def test_only_states_that_need_action_are_coloured(qtbot):
    from PySide6.QtCore import Qt

    from app.gui.campaign_tree import CampaignTree

    tree = CampaignTree()
    qtbot.addWidget(tree)
    items = {s: tree._item(tree.invisibleRootItem(), s, s, "epoch", s) for s in
             ("imported", "planned", "measured", "processed", "warning", "problem")}
    for s, it in items.items():
        coloured = it.foreground(1).style() != Qt.NoBrush  # a brush set: the default text colour otherwise
        assert coloured == (s in ("warning", "problem")), s
        assert it.icon(1).isNull() == (s not in ("warning", "problem")), s

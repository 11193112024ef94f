"""GUI test fixtures: the campaign fixtures of tests/projects, isolated settings, no blocking dialogs."""
from __future__ import annotations

import pytest

pytest.importorskip("PySide6")

from tests.projects.conftest import field, field_copy, processed, processed_copy  # noqa: E402,F401  (fixtures)


@pytest.fixture
def errors(monkeypatch):
    """Messages the GUI showed in error dialogs (the dialogs themselves are not opened)."""
    shown = []
    from PySide6.QtWidgets import QMessageBox

    monkeypatch.setattr(QMessageBox, "critical", staticmethod(lambda parent, title, text, *a, **k: shown.append(
        (title, text))))
    monkeypatch.setattr(QMessageBox, "question", staticmethod(lambda *a, **k: QMessageBox.Yes))
    return shown


@pytest.fixture
def window(qtbot, tmp_path, errors):
    from PySide6.QtCore import QSettings

    from app.gui.main_window import MainWindow

    QSettings.setPath(QSettings.IniFormat, QSettings.UserScope, str(tmp_path / "settings"))
    win = MainWindow(demo_dir=str(tmp_path / "no-demo"))
    qtbot.addWidget(win)
    win.resize(1400, 900)
    win.show()
    yield win
    win.jobs.cancel()
    win.jobs.wait()


def wait_job(qtbot, win, timeout=180_000):
    qtbot.waitUntil(lambda: not win.jobs.busy, timeout=timeout)
    qtbot.wait(50)

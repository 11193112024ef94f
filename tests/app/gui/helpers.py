"""What the GUI tests do as a user would: mouse drags, menu entries, dialogs answered, files chosen."""
from __future__ import annotations

from collections import deque
from collections.abc import Callable

from PySide6.QtCore import QEvent, QPoint, QPointF, QRect, Qt, QTimer
from PySide6.QtGui import QMouseEvent
from PySide6.QtWidgets import (
    QAbstractButton,
    QAbstractSpinBox,
    QApplication,
    QComboBox,
    QFileDialog,
    QLineEdit,
    QWidget,
)


def _send(widget, kind, pos, buttons):
    button = Qt.LeftButton if kind != QEvent.MouseMove else Qt.NoButton
    ev = QMouseEvent(kind, QPointF(pos), widget.mapToGlobal(QPointF(pos)), button, buttons, Qt.NoModifier)
    QApplication.sendEvent(widget, ev)


def drag(view, start, end, steps=5):
    """Press, move and release the left button in a graphics view's viewport (scene coordinates)."""
    vp = view.viewport()
    a, b = view.mapFromScene(start), view.mapFromScene(end)
    _send(vp, QEvent.MouseButtonPress, a, Qt.LeftButton)
    for k in range(1, steps + 1):
        p = a + (b - a) * (k / steps)
        _send(vp, QEvent.MouseMove, p, Qt.LeftButton)
    _send(vp, QEvent.MouseButtonRelease, b, Qt.NoButton)


def menu_action(win, menu: str, entry: str):
    """The QAction ``menu ▸ entry`` of a window's menu bar (the texts without their '&')."""
    for m in win.menuBar().actions():
        if m.text().replace("&", "") == menu:
            for a in m.menu().actions():
                if a.text().replace("&", "") == entry:
                    return a
    raise LookupError(f"no menu entry {menu} ▸ {entry}")


def menu_actions(win) -> list:
    """Every entry of every menu: (menu, entry, QAction)."""
    out = []
    for m in win.menuBar().actions():
        for a in m.menu().actions():
            if not a.isSeparator() and a.menu() is None:
                out.append((m.text().replace("&", ""), a.text().replace("&", ""), a))
    return out


def answer(cls, fill: Callable, *, accept: bool = True, tries: int = 400) -> list:
    """Answer the next modal dialog of type ``cls`` when it opens: ``fill(dialog)``, then OK (or Cancel).

    Returns a list that holds the dialog once it was answered.
    """
    answered: list = []

    def attempt(left=tries):
        w = QApplication.activeModalWidget()
        if isinstance(w, cls):
            fill(w)
            answered.append(w)
            (w.accept if accept else w.reject)()
        elif left > 0:
            QTimer.singleShot(25, lambda: attempt(left - 1))
    QTimer.singleShot(25, attempt)
    return answered


class FileChooser:
    """Stands in for the file dialogs: hands out the queued answers and records where each dialog opened."""

    def __init__(self, monkeypatch):
        self.answers: deque = deque()
        self.opened_in: list[tuple[str, str]] = []  # (title, start folder or file)
        for name in ("getOpenFileName", "getSaveFileName"):
            monkeypatch.setattr(QFileDialog, name, staticmethod(self._one))
        monkeypatch.setattr(QFileDialog, "getOpenFileNames", staticmethod(self._many))
        monkeypatch.setattr(QFileDialog, "getExistingDirectory", staticmethod(self._folder))

    def will_choose(self, *paths) -> None:
        self.answers.extend(str(p) if not isinstance(p, list) else [str(x) for x in p] for p in paths)

    def _next(self, title, start):
        self.opened_in.append((title, str(start)))
        return self.answers.popleft() if self.answers else ""

    def _one(self, parent=None, title="", start="", filter_="", *a, **k):
        return self._next(title, start), filter_

    def _many(self, parent=None, title="", start="", filter_="", *a, **k):
        v = self._next(title, start)
        return (v if isinstance(v, list) else ([v] if v else [])), filter_

    def _folder(self, parent=None, title="", start="", *a, **k):
        return self._next(title, start)


CONTROLS = (QAbstractButton, QComboBox, QAbstractSpinBox, QLineEdit)


def controls_out_of_reach(win) -> list[str]:
    """The visible controls of a window that do not lie wholly inside it (off screen on a small one)."""
    bounds = QRect(QPoint(0, 0), win.size())
    out = []
    for w in win.findChildren(QWidget):
        if not isinstance(w, CONTROLS) or not w.isVisible() or w.window() is not win:
            continue
        if w.parent() is not None and type(w.parent()).__name__ in ("QTabBar", "QScrollBar"):
            continue  # the tab bar's own scroll arrows
        r = QRect(w.mapTo(win, QPoint(0, 0)), w.size())
        if not bounds.contains(r):
            out.append(f"{type(w).__name__} {getattr(w, 'text', lambda: '')()!r} at {r.getRect()}")
    return out

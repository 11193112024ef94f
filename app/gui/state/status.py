"""What the status bar says about the application's work (no Qt here).

A job goes ``started`` → ``progress`` … → one of ``done`` / ``failed`` / ``cancelled``; the user may
ask to cancel it in between (``cancelling``). The rules the status bar keeps:

- a job that ends never leaves its last progress line behind: it says how it ended;
- a job's own result line (``report written to …``) is not overwritten by the generic "done" that
  follows it, nor by passing information, for :data:`HOLD_S` seconds;
- a failure stays until the next job starts (the dialog may have been closed without reading);
- a failure resets the progress indicator (no Cancel left enabled) before it is reported;
- a line about a job's outcome belongs to the tab it was said on: another tab shown clears it
  (:meth:`StatusLine.view_changed`), so "Comparing …: done" does not linger over the map.

>>> s = StatusLine(clock=lambda: 0.0)
>>> s.started("Writing the report"); s.message.text
'Writing the report…'
>>> s.result("report written to r.pdf"); s.finished(ok=True); s.message.text
'report written to r.pdf'
>>> s.started("Importing epoch e1"); s.cancelling(); s.message.text
'Importing epoch e1: cancelling…'
>>> s.cancelled(); s.message.text
'Importing epoch e1: cancelled'
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from psygnal import Signal

#: Seconds a job's result line stays before information may replace it.
HOLD_S = 8.0
#: Milliseconds the status bar shows a finished job's line (0: until replaced).
DONE_TIMEOUT_MS = 15_000
#: The kinds of line that belong to the tab they were said on (cleared when another tab is shown).
SCOPED = ("done", "result", "cancelled", "info")


@dataclass(frozen=True)
class StatusMessage:
    """One status-bar line: its text, what it is about and how long it stays (ms, 0: until replaced).

    ``kind`` is ``busy`` (a job runs), ``cancelling``, ``done``, ``result`` (a job's own outcome),
    ``failed``, ``cancelled``, ``info`` or ``""`` (nothing to say).
    """

    text: str
    kind: str = ""
    timeout_ms: int = 0
    view: str = ""  # the tab shown when it was said ("" : the whole window)


class StatusLine:
    """The status bar's line and the running job's progress; ``changed(message)`` after every change."""

    changed = Signal(object)
    #: ``(running, fraction, cancelling)`` whenever the progress indicator should change.
    progress_changed = Signal(bool, float, bool)

    def __init__(self, *, clock: Callable[[], float] = time.monotonic):
        self._clock = clock
        self.message = StatusMessage("")
        self.title: str | None = None  # the running job
        self.fraction = 0.0
        self.is_cancelling = False
        self._held_until = -1.0
        self._result_posted = False
        self.view = ""  # the tab shown now

    @property
    def running(self) -> bool:
        return self.title is not None

    # ------------------------------------------------------------------ a job's life
    def started(self, title: str) -> None:
        self.title, self.fraction, self.is_cancelling, self._result_posted = title, 0.0, False, False
        self._held_until = -1.0
        self._show(StatusMessage(f"{title}…", "busy"))
        self.progress_changed.emit(True, 0.0, False)

    def progress(self, fraction: float, message: str = "") -> None:
        if self.title is None:
            return
        self.fraction = min(1.0, max(0.0, float(fraction)))
        self.progress_changed.emit(True, self.fraction, self.is_cancelling)
        if message and not self.is_cancelling:
            self._show(StatusMessage(f"{self.title}: {message}", "busy"))

    def cancelling(self) -> None:
        """The user asked to stop the running job; it stops at its next progress step."""
        if self.title is None or self.is_cancelling:
            return
        self.is_cancelling = True
        self._show(StatusMessage(f"{self.title}: cancelling…", "cancelling"))
        self.progress_changed.emit(True, self.fraction, True)

    def result(self, text: str) -> None:
        """The job's own outcome in its words (``report written to …``): kept over the generic "done"."""
        self._result_posted = True
        self._show(StatusMessage(text, "result", DONE_TIMEOUT_MS))
        self._held_until = self._clock() + HOLD_S

    def finished(self, *, ok: bool) -> None:
        """The job ended (its error or cancellation, if any, was reported first)."""
        title, self.title = self.title, None
        self.progress_changed.emit(False, 1.0 if ok else self.fraction, False)
        if ok and not self._result_posted and title is not None:
            self._show(StatusMessage(f"{title}: done", "done", DONE_TIMEOUT_MS))
            self._held_until = self._clock() + HOLD_S

    def failed(self, message: str) -> None:
        title = self.title or "The last task"
        self.progress_changed.emit(False, 0.0, False)  # before the error box: no bar at 10 % with Cancel enabled
        self._show(StatusMessage(f"{title} failed: {message}", "failed"))
        self._held_until = float("inf")  # until the next job starts

    def cancelled(self) -> None:
        title = self.title or "The last task"
        self._show(StatusMessage(f"{title}: cancelled", "cancelled", DONE_TIMEOUT_MS))
        self._held_until = self._clock() + HOLD_S

    # ------------------------------------------------------------------ other lines
    def info(self, text: str, timeout_ms: int = DONE_TIMEOUT_MS) -> bool:
        """Passing information; False (not shown) while a job runs or a job's outcome is still fresh."""
        if self.title is not None or self._clock() < self._held_until:
            return False
        self._show(StatusMessage(text, "info", timeout_ms))
        return True

    def view_changed(self, view: str) -> None:
        """Another tab is shown: a line about an outcome said on another tab goes (a running job's stays)."""
        self.view = view
        m = self.message
        if m.kind in SCOPED and m.view and m.view != view:
            self._held_until = -1.0
            self._show(StatusMessage(""))

    def _show(self, message: StatusMessage) -> None:
        if message.kind in SCOPED and not message.view:
            message = StatusMessage(message.text, message.kind, message.timeout_ms, self.view)
        self.message = message
        self.changed.emit(message)

"""The application's state without Qt: the open campaign, the selection, the status line, the next
step, the map's plan under edit and the results the views show.

The window's views subscribe to these events (psygnal signals) and draw what they carry; the
commands change the state; nothing here knows a widget. The campaign is opened briefly for each
read (shared lock) and for each change (exclusive lock, inside a job), so the command line can work
on the same campaign between the application's actions.

Events of :class:`AppState`:

- ``opened(name)`` / ``closed()``: a campaign was opened or closed;
- ``refreshed(snapshot)``: the campaign's contents were read again (a :class:`Snapshot`);
- ``selection_changed(selection)``: a :class:`Selection`;
- ``details_changed(html)``: the details of the focused item;
- ``next_step_changed(step)``: a :class:`app.gui.state.next_step.NextStep`;
- ``view_requested(name)``: a command wants a view shown (``map``, ``fine``, ``cloud``, ``camera``,
  ``stations``, ``analysis``, ``displacements``);
- ``error(title, message)``: something failed; the message is one line in the application's words.
"""
from __future__ import annotations

import html
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from psygnal import Signal

from app.gui.state.campaign_access import CampaignAccess
from app.gui.state.details_html import campaign_html, epoch_html, reflector_html, series_html
from app.gui.state.map_state import MapState
from app.gui.state.next_step import NextStep, next_step
from app.gui.state.status import StatusLine
from app.gui.state.words import in_app_words
from common.errors import SurveyError
from projects.results.status import campaign_status
from projects.series.camera import crossval_summaries, load_series, series_records
from projects.series.context import plot_context
from projects.store.history import histories
from vision.crossval import CrossValidation

#: The views a command may ask for, by name.
VIEWS = ("displacements", "map", "fine", "cloud", "camera", "stations", "analysis")


@dataclass(frozen=True)
class Snapshot:
    """What the campaign holds, read at once for the views.

    ``status`` is :func:`projects.results.status.campaign_status` (every epoch's state by
    :func:`projects.results.state.epoch_state`), ``reflectors`` and ``series`` (camera series) are
    store records, ``histories`` maps a target id to its :class:`projects.store.history.DisplacementHistory`,
    ``context`` is a :class:`projects.series.context.PlotContext`.
    """

    status: dict = field(default_factory=lambda: {"name": "", "span_m": None, "baseline": None, "epochs": [],
                                                  "targets": []})
    reflectors: tuple = ()
    series: tuple = ()
    histories: dict = field(default_factory=dict)
    context: Any = None

    @property
    def epochs(self) -> list[str]:
        return [e["epoch"] for e in self.status["epochs"]]

    def epoch_row(self, label: str | None) -> dict | None:
        return next((e for e in self.status["epochs"] if e["epoch"] == label), None)


@dataclass(frozen=True)
class Selection:
    """The selected target and epoch, and what the details show (``focus``: kind and key; kind is
    ``campaign``, ``reflector``, ``epoch`` or ``series``)."""

    reflector: str | None = None
    epoch: str | None = None
    focus: tuple[str, str] = ("campaign", "")


def read_snapshot(access) -> Snapshot:
    """Everything the views show of a campaign, in one shared-lock read."""
    with access.read() as c:
        return Snapshot(campaign_status(c), tuple(c.reflectors()), tuple(series_records(c)), histories(c),
                        plot_context(c))


class Outputs:
    """Results of the application's jobs, for the views that show them.

    Events: ``inspection(TargetInspection)``, ``cloud(DisplayCloud)``, ``stations(advice, layout)``,
    ``analysis(doc)``, ``crossval(CrossValidation, camera series)``; and ``message(view, text)`` when a
    view has nothing to show and says why.
    """

    inspection = Signal(object)
    cloud = Signal(object)
    stations = Signal(object, object)
    analysis = Signal(object)
    crossval = Signal(object, object)
    message = Signal(str, str)


class AppState:
    """The open campaign and everything the views show of it (see the module's docstring for the events)."""

    opened = Signal(str)
    closed = Signal()
    refreshed = Signal(object)
    selection_changed = Signal(object)
    details_changed = Signal(str)
    next_step_changed = Signal(object)
    view_requested = Signal(str)
    error = Signal(str, str)

    def __init__(self) -> None:
        self.access: CampaignAccess | None = None
        self.name = ""
        self.snapshot = Snapshot()
        self.selection = Selection()
        self.status = StatusLine()
        self.map = MapState()
        self.outputs = Outputs()
        self.visible_view = ""
        self.next: NextStep | None = None

    # ------------------------------------------------------------------ the campaign
    @property
    def is_open(self) -> bool:
        return self.access is not None

    @property
    def folder(self) -> Path | None:
        return None if self.access is None else self.access.folder

    def open(self, folder: str | Path) -> bool:
        """Open a campaign folder; False (and ``error`` emitted) when it holds none."""
        access = CampaignAccess(folder)
        try:
            with access.read() as c:
                name = c.name
        except SurveyError as exc:
            self.report_error("Open campaign", str(exc))
            return False
        self.access, self.name = access, name
        self.snapshot, self.selection = Snapshot(), Selection()
        self.map.clear("")
        self.opened.emit(name)
        self.refresh()
        return True

    def close(self) -> None:
        self.access, self.name = None, ""
        self.snapshot, self.selection, self.next = Snapshot(), Selection(), None
        self.map.clear("")
        self.closed.emit()

    def refresh(self) -> None:
        """Read the campaign again (after a change, or on request) and tell every view."""
        if self.access is None:
            return
        try:
            snap = read_snapshot(self.access)
        except SurveyError as exc:
            self.report_error("Reload campaign", str(exc))
            return
        self.snapshot = snap
        if self.selection.epoch is not None and snap.epoch_row(self.selection.epoch) is None:
            self.selection = replace(self.selection, epoch=None)
        self.refreshed.emit(snap)
        self._update_details()
        self._update_next_step()
        self._load_visible(reload=True)

    def read(self):
        """The campaign opened read-only, for ``with state.read() as c``."""
        if self.access is None:
            raise SurveyError("no campaign is open; open or create one (File menu)")
        return self.access.read()

    # ------------------------------------------------------------------ selection and views
    @property
    def epoch_or_latest(self) -> str | None:
        """The selected epoch, else the campaign's latest (None without epochs)."""
        eps = self.snapshot.epochs
        return self.selection.epoch or (eps[-1] if eps else None)

    def select(self, *, reflector: Any = ..., epoch: Any = ..., focus: tuple[str, str] | None = None) -> None:
        """Change the selection (arguments left out keep their value).

        The details follow what was selected last: ``focus`` when given, else the target when only a
        target was given, else the epoch.
        """
        sel = self.selection
        new = replace(sel, reflector=sel.reflector if reflector is ... else reflector,
                      epoch=sel.epoch if epoch is ... else epoch)
        if focus is None:
            if reflector is not ... and epoch is ... and reflector:
                focus = ("reflector", reflector)
            elif epoch is not ... and epoch:
                focus = ("epoch", epoch)
        if focus is not None:
            new = replace(new, focus=focus)
        if new == sel:
            return
        self.selection = new
        self.selection_changed.emit(new)
        if new.focus != sel.focus:
            self._update_details()
        if new.epoch != sel.epoch:
            self._update_next_step()
        self._load_visible()

    def show_view(self, name: str) -> None:
        """The window shows the view ``name`` now: load what it needs for the selection."""
        self.visible_view = name
        self.status.view_changed(name)
        self._load_visible()

    def request_view(self, name: str) -> None:
        """Ask the window to show the view ``name`` (one of :data:`VIEWS`)."""
        if name not in VIEWS:
            raise ValueError(f"unknown view {name!r}")
        self.view_requested.emit(name)

    def _load_visible(self, *, reload: bool = False) -> None:
        """Views that read the campaign load lazily, when they are shown (and again after a change)."""
        if self.access is None:
            return
        try:
            if self.visible_view == "map":
                self.map.show(self.access, self.epoch_or_latest, reload=reload)
            elif self.visible_view == "camera":
                self._load_camera()
        except SurveyError as exc:
            self.report_error("Show the epoch", str(exc))

    def _load_camera(self) -> None:
        with self.read() as c:
            sums = crossval_summaries(c)
            cam = load_series(c, sums[0]["series"])[1] if sums else None
        if sums:
            self.outputs.crossval.emit(CrossValidation.from_json(sums[0]), cam)
        else:
            have = bool(self.snapshot.series)
            self.outputs.message.emit("camera", "No cross-validation yet: " + (
                "Camera ▸ Cross-validate with LiDAR." if have else
                "import a camera series (Camera ▸ Import series…), then Camera ▸ Cross-validate with LiDAR."))

    # ------------------------------------------------------------------ details and guidance
    def _update_details(self) -> None:
        self.details_changed.emit(self.details_html())

    def details_html(self) -> str:
        """HTML of the focused item (the campaign, a target, an epoch or a camera series)."""
        if self.access is None:
            return ""
        kind, key = self.selection.focus
        try:
            with self.read() as c:
                if kind == "reflector":
                    return reflector_html(c, key)
                if kind == "epoch":
                    return epoch_html(c, key)
                if kind == "series":
                    row = next((r for r in self.snapshot.series if r.name == key), None)
                    if row is not None:
                        return series_html(row)
                return campaign_html(c, self.snapshot.status)
        except SurveyError as exc:

            return f"<p>{html.escape(in_app_words(str(exc)))}</p>"

    def _update_next_step(self) -> None:
        step = None if self.access is None else next_step(self.snapshot.status, self.selection.epoch)
        if step != self.next:
            self.next = step
            self.next_step_changed.emit(step)

    # ------------------------------------------------------------------ messages
    def job_failed(self, title: str, message: str, kind: str) -> None:
        """A background job ended without a result (``kind``: ``error``, ``bug`` or ``cancelled``)."""
        if kind == "cancelled":
            self.status.cancelled()
            return
        words = in_app_words(message)
        self.status.failed(words)
        self.error.emit(title, words)

    def report_error(self, title: str, message: str) -> None:
        """Tell the user something failed, in the application's words."""
        self.error.emit(title, in_app_words(message))

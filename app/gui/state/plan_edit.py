"""The plan being edited on the map, with undo and redo (no Qt here).

The map view draws what a :class:`PlanEditor` holds and reports the user's gestures to it; the
editor keeps the windows, recomputes each edited window's steps, points and seconds
(:func:`lidar.plan.edit_roi`) and remembers every committed change so it can be undone.

A drag is one change: while the mouse moves the window follows (``final=False``), and the release
(``final=True``) commits it, so one undo puts the window back where the drag started.

>>> from lidar.plan import AngularWindow, RoiPlan, ScanPlan
>>> from lidar.scanner_catalogue import DEFAULT_SCANNER, get_scanner
>>> w = AngularWindow(60.0, 60.4, 10.0, 10.4, 0.01, 0.01)
>>> plan = ScanPlan("e1", get_scanner(DEFAULT_SCANNER), (RoiPlan("M1", "measurement", w, 20.0, 10.0, 1600, 1000, 60.0),),
...                 1000, 1000, 3600.0)
>>> ed = PlanEditor(plan)
>>> ed.remove(["M1"])
True
>>> len(ed.rois), ed.dirty, ed.can_undo
(0, True, True)
>>> ed.undo()
True
>>> [r.reflector for r in ed.rois], ed.dirty, ed.can_redo
(['M1'], False, True)
"""
from __future__ import annotations

from collections.abc import Callable, Iterable

from psygnal import Signal

from common.errors import SurveyError
from lidar.plan import RoiPlan, ScanPlan, edit_roi, with_rois

#: How many changes can be undone.
UNDO_DEPTH = 200


def _editable(plan: ScanPlan | None) -> tuple[RoiPlan, ...]:
    """The windows a user edits: all but the closure, which repeats its target's window at the visit's end."""
    return () if plan is None else tuple(r for r in plan.rois if not r.closure)


class PlanEditor:
    """One epoch's plan under edit: its windows, whether they differ from the stored plan, undo and redo.

    Parameters
    ----------
    stored : ScanPlan or None
        The plan as stored in the campaign (None: the epoch has no plan; nothing can be edited).
    on_change : callable, optional
        Connected to :attr:`changed`.

    Events: ``changed()`` after every change of the windows or of what is saved (load, edit, undo,
    redo, revert, save).
    """

    changed = Signal()

    def __init__(self, stored: ScanPlan | None = None, *, on_change: Callable[[], None] | None = None):
        if on_change is not None:
            self.changed.connect(on_change)
        self.load(stored)

    # ------------------------------------------------------------------ state
    def load(self, stored: ScanPlan | None) -> None:
        """Start editing ``stored`` afresh (no history)."""
        self.stored = stored
        # the closure window follows its target's window (lidar.plan.with_rois): it is not edited on its own
        self._rois: tuple[RoiPlan, ...] = _editable(stored)
        self._saved = self._rois
        self._undo: list[tuple[RoiPlan, ...]] = []
        self._redo: list[tuple[RoiPlan, ...]] = []
        self._drag_origin: tuple[RoiPlan, ...] | None = None
        self._notify()

    @property
    def rois(self) -> tuple[RoiPlan, ...]:
        """The windows as they are now, in drawing order."""
        return self._rois

    @property
    def plan(self) -> ScanPlan | None:
        """The edited plan (the stored plan with the current windows), or None when there is none."""
        if self.stored is None:
            return None
        return self.stored if self._rois == _editable(self.stored) else with_rois(self.stored, self._rois)

    @property
    def dirty(self) -> bool:
        """Whether the windows differ from the last saved ones."""
        return self._rois != self._saved

    @property
    def can_undo(self) -> bool:
        return bool(self._undo)

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    def roi(self, reflector: str) -> RoiPlan | None:
        return next((r for r in self._rois if r.reflector == reflector), None)

    # ------------------------------------------------------------------ changes
    def add(self, roi: RoiPlan) -> None:
        """Add a window (replacing the target's window if it has one)."""
        self._commit(tuple(r for r in self._rois if r.reflector != roi.reflector) + (roi,))

    def remove(self, reflectors: Iterable[str]) -> bool:
        """Delete the windows of ``reflectors``; False when none of them had one."""
        gone = set(reflectors)
        kept = tuple(r for r in self._rois if r.reflector not in gone)
        if len(kept) == len(self._rois):
            return False
        self._commit(kept)
        return True

    def reshape(self, reflector: str, window: dict, *, final: bool = True) -> RoiPlan | None:
        """Move or resize a target's window to ``window`` (``phi_min_deg``, ``phi_max_deg``,
        ``theta_min_deg``, ``theta_max_deg``), with steps for the plan's points.

        While a drag goes on (``final=False``) the window follows without an undo step; the release
        (``final=True``) commits the whole drag as one. Returns the new window, or None when the
        shape is impossible (dragged off the sky): the window keeps its last valid shape.
        """
        old = self.roi(reflector)
        if old is None or self.stored is None:
            return None
        ow = old.window
        same = all(abs(float(window[k]) - getattr(ow, k)) < 1e-6
                   for k in ("phi_min_deg", "phi_max_deg", "theta_min_deg", "theta_max_deg"))
        try:
            new = old if same else edit_roi(old, profile=self.stored.profile, **window)
        except (SurveyError, ValueError):
            new = None
        if self._drag_origin is None:
            self._drag_origin = self._rois
        if new is not None:
            self._rois = tuple(new if r.reflector == reflector else r for r in self._rois)
        if final:
            origin, self._drag_origin = self._drag_origin, None
            if self._rois != origin:
                self._push(origin)
        self._notify()
        return new

    def undo(self) -> bool:
        """Take back the last change; False when there is none."""
        return self._step(self._undo, self._redo)

    def redo(self) -> bool:
        """Make the last undone change again; False when there is none."""
        return self._step(self._redo, self._undo)

    def revert(self) -> None:
        """Back to the last saved windows (itself a change that can be undone)."""
        if self._rois != self._saved:
            self._commit(self._saved)

    def mark_saved(self, rois: Iterable[RoiPlan] | None = None) -> None:
        """The current windows (or ``rois``, the ones a save wrote) are now what the campaign holds."""
        self._saved = self._rois if rois is None else tuple(r for r in rois if not r.closure)
        self._notify()

    # ------------------------------------------------------------------ internals
    def _commit(self, rois: tuple[RoiPlan, ...]) -> None:
        self._push(self._rois)
        self._rois = tuple(rois)
        self._notify()

    def _push(self, previous: tuple[RoiPlan, ...]) -> None:
        self._undo.append(previous)
        del self._undo[:-UNDO_DEPTH]
        self._redo.clear()

    def _step(self, source: list, target: list) -> bool:
        if not source:
            return False
        target.append(self._rois)
        self._rois = source.pop()
        self._notify()
        return True

    def _notify(self) -> None:
        self.changed.emit()

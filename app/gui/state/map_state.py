"""The epoch shown on the reflectance map: its stored preview and the plan under edit (no Qt here).

The map view draws what a :class:`MapState` holds: ``preview_changed(label, preview, plan)`` when another
epoch's map is loaded (or ``message(text)`` when there is none to show), then the windows from
:attr:`MapState.editor` (a :class:`app.gui.state.plan_edit.PlanEditor`, with its own ``changed``
event).
"""
from __future__ import annotations

from psygnal import Signal

from app.gui.state.map_geometry import CellRect, window_from_cells
from app.gui.state.plan_edit import PlanEditor
from common.errors import InputError
from lidar.angles import AngularWindow
from lidar.plan import RoiPlan, ScanPlan, holds, target_extent


class MapState:
    """One epoch's map preview and its plan under edit."""

    preview_changed = Signal(str, object, object)
    message = Signal(str)

    def __init__(self) -> None:
        self.label: str | None = None
        self.preview = None  # projects.store.previews.MapPreview
        self.editor = PlanEditor()
        self.diameters: dict[str, float] = {}  # each target's disc, m

    def show(self, access, label: str | None, *, reload: bool = False) -> None:
        """Show ``label``'s map and plan; the epoch already shown stays as it is (its windows may be under
        edit) unless ``reload`` asks for what the campaign now holds and nothing is left unsaved."""
        if label is None:
            self.clear("No epoch yet: add one (Epoch ▸ Add epoch…).")
            return
        if self.editor.stored is not None and self.label == label and (self.editor.dirty or not reload):
            return
        with access.read() as c:
            preview = c.map_preview(label)
            plan = c.plan(label)
            self.diameters = {r.id: float(r.diameter_m) for r in c.reflectors()}
        if preview is None:
            self.clear(f"Epoch {label} has not been planned yet: Epoch ▸ Plan the selected epoch (or Process).")
            return
        self.label, self.preview = label, preview
        self.preview_changed.emit(label, preview, plan)
        self.editor.load(plan)

    def clear(self, text: str) -> None:
        """Nothing to show, and why."""
        self.label, self.preview = None, None
        self.message.emit(text)
        self.editor.load(None)

    def extent(self, reflector: str) -> AngularWindow | None:
        """The least a window of ``reflector`` must hold: its disc and a margin (:func:`lidar.plan.target_extent`)
        where the map found it; None for a target the map did not find (its window may go where the user sees it)."""
        if self.preview is None:
            return None
        match = next((m for m in self.preview.identification.matches if m.id == reflector), None)
        if match is None or match.detection is None:
            return None
        return target_extent(match.xyz_socs, diameter_m=self.diameters.get(reflector, 0.05))

    def cut_targets(self, plan: ScanPlan | None) -> list[RoiPlan]:
        """The windows of ``plan`` that do not hold their whole target: it would give fewer points than expected."""
        out = []
        for roi in plan.rois if plan is not None else ():
            ext = self.extent(roi.reflector)
            if ext is not None and not roi.closure and not holds(roi.window, ext):
                out.append(roi)
        return out

    def free_targets(self, reflectors) -> list[str]:
        """The ids of ``reflectors`` (records, not retired) that have no window in the plan yet."""
        taken = {r.reflector for r in self.editor.rois}
        return [r.id for r in reflectors if not r.retired and r.id not in taken]

    def window_for(self, rect: CellRect, reflector) -> RoiPlan:
        """A new window for ``reflector`` (a record) from a rectangle drawn on the map (cell units)."""
        plan = self.editor.plan
        if plan is None or self.preview is None:
            raise InputError("this epoch has no plan to add a window to; plan it first (Epoch ▸ Plan the selected "
                             "epoch)")
        return window_from_cells(self.preview, plan, rect, reflector.id, reflector)

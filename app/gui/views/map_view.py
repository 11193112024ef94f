"""The reflectance map of an epoch with its detections and the fine-scan windows, which can be moved,
resized, added and deleted; the plan's points and seconds follow live, and the plan can be saved.

Scene coordinates are map cells: x = (phi - phi0) / step (azimuth, wrapping), y = (theta - theta0) / step.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np
from matplotlib import colormaps
from PySide6.QtCore import QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QImage, QKeySequence, QPainter, QPen, QPixmap, QShortcut
from PySide6.QtWidgets import (QAbstractItemView, QGraphicsEllipseItem, QGraphicsItem, QGraphicsRectItem,
                               QGraphicsScene, QGraphicsSimpleTextItem, QGraphicsView, QHBoxLayout, QLabel,
                               QPushButton, QSplitter, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget)

from app.gui.state.map_geometry import CellRect, window_of_cells
from app.gui.state.plan_edit import PlanEditor
from lidar.plan import RoiPlan, ScanPlan

GROUP_COLOURS = {"reference": QColor("#ff9f1c"), "measurement": QColor("#2ec4b6"), "": QColor("#e71d36")}


def map_image(max_intensity: np.ndarray) -> QImage:
    """Colour image (viridis, empty cells dark grey) of a (rows, cols) intensity map in [0, 1]."""
    rgba = (colormaps["viridis"](np.nan_to_num(max_intensity, nan=0.0)) * 255).astype(np.uint8)
    rgba[np.isnan(max_intensity)] = (40, 40, 40, 255)
    h, w = max_intensity.shape
    img = QImage(np.ascontiguousarray(rgba).data, w, h, 4 * w, QImage.Format_RGBA8888)
    return img.copy()  # own the pixels


def cells(rect: QRectF) -> CellRect:
    """A scene rectangle as plain map-cell values."""
    return CellRect(rect.left(), rect.top(), rect.width(), rect.height())


class MapGeometry:
    """Conversions between scanner angles and scene coordinates of one map."""

    def __init__(self, theta0: float, phi0: float, step: float):
        self.theta0, self.phi0, self.step = theta0, phi0, step

    def rect_of(self, roi: RoiPlan) -> QRectF:
        w = roi.window
        x0 = np.mod(w.phi_min_deg - self.phi0, 360.0) / self.step
        y0 = (w.theta_min_deg - self.theta0) / self.step
        return QRectF(x0, y0, (w.phi_max_deg - w.phi_min_deg) / self.step, (w.theta_max_deg - w.theta_min_deg) / self.step)

    def window_of(self, rect: QRectF) -> dict:
        return window_of_cells(cells(rect), self.theta0, self.phi0, self.step)

    def point_of(self, theta: float, phi: float) -> QPointF:
        return QPointF(np.mod(phi - self.phi0, 360.0) / self.step, (theta - self.theta0) / self.step)


class RoiItem(QGraphicsRectItem):
    """A movable window; drag its edges or corners to resize it. ``on_change(item, final)`` is called
    while it moves (final False) and when the mouse is released (final True)."""
    HANDLE_PX = 7

    def __init__(self, roi: RoiPlan, rect: QRectF, on_change: Callable):
        super().__init__(QRectF(0, 0, rect.width(), rect.height()))
        self.setPos(rect.topLeft())
        self.roi = roi
        self.on_change = on_change
        colour = GROUP_COLOURS.get(roi.group, GROUP_COLOURS[""])
        pen = QPen(colour, 2)
        pen.setCosmetic(True)
        self.setPen(pen)
        self.setBrush(QBrush(QColor(colour.red(), colour.green(), colour.blue(), 40)))
        self.setFlags(QGraphicsItem.ItemIsMovable | QGraphicsItem.ItemIsSelectable
                      | QGraphicsItem.ItemSendsGeometryChanges)
        self.setAcceptHoverEvents(True)
        self.label = QGraphicsSimpleTextItem(roi.reflector, self)
        self.label.setBrush(QBrush(colour))
        self.label.setFont(QFont("Sans", 9, QFont.Bold))
        self.label.setFlag(QGraphicsItem.ItemIgnoresTransformations)
        self._edges = None

    def scene_rect(self) -> QRectF:
        return self.mapRectToScene(self.rect())

    def _scale(self) -> float:
        view = self.scene().views()[0] if self.scene() and self.scene().views() else None
        return max(view.transform().m11(), 1e-9) if view else 1.0

    def _edges_at(self, pos: QPointF):
        """The edges (nearest one per axis) within a few screen pixels of ``pos``."""
        tol = self.HANDLE_PX / self._scale()
        r = self.rect()
        edges = set()
        dl, dr = abs(pos.x() - r.left()), abs(pos.x() - r.right())
        if min(dl, dr) < tol:
            edges.add("l" if dl < dr else "r")
        dt, db = abs(pos.y() - r.top()), abs(pos.y() - r.bottom())
        if min(dt, db) < tol:
            edges.add("t" if dt < db else "b")
        return edges

    def hoverMoveEvent(self, event):
        e = self._edges_at(event.pos())
        shape = Qt.SizeAllCursor
        if e in ({"l", "t"}, {"r", "b"}):
            shape = Qt.SizeFDiagCursor
        elif e in ({"r", "t"}, {"l", "b"}):
            shape = Qt.SizeBDiagCursor
        elif e & {"l", "r"}:
            shape = Qt.SizeHorCursor
        elif e & {"t", "b"}:
            shape = Qt.SizeVerCursor
        self.setCursor(shape)
        super().hoverMoveEvent(event)

    def mousePressEvent(self, event):
        self._edges = self._edges_at(event.pos()) or None
        if self._edges:
            event.accept()
            return
        super().mousePressEvent(event)

    def mouseMoveEvent(self, event):
        if self._edges:
            r = QRectF(self.rect())
            p = event.pos()
            min_size = 3.0 / self._scale()  # a few screen pixels
            if "l" in self._edges:
                r.setLeft(min(p.x(), r.right() - min_size))
            if "r" in self._edges:
                r.setRight(max(p.x(), r.left() + min_size))
            if "t" in self._edges:
                r.setTop(min(p.y(), r.bottom() - min_size))
            if "b" in self._edges:
                r.setBottom(max(p.y(), r.top() + min_size))
            self.set_scene_rect(self.mapRectToScene(r))
            self.on_change(self, False)
            return
        super().mouseMoveEvent(event)

    def mouseReleaseEvent(self, event):
        self._edges = None
        super().mouseReleaseEvent(event)
        self.on_change(self, True)

    def itemChange(self, change, value):
        if change == QGraphicsItem.ItemPositionHasChanged and self.scene() is not None and not self._edges:
            self.on_change(self, False)
        return super().itemChange(change, value)

    def set_scene_rect(self, rect: QRectF) -> None:
        self.prepareGeometryChange()
        self.setPos(rect.topLeft())
        self.setRect(QRectF(0, 0, rect.width(), rect.height()))


class MapGraphicsView(QGraphicsView):
    """Zoom with the wheel, pan by dragging the background; in draw mode a drag draws a new window."""
    drawn = Signal(QRectF)

    def __init__(self, scene, parent=None):
        super().__init__(scene, parent)
        self.setRenderHint(QPainter.Antialiasing)
        self.setDragMode(QGraphicsView.ScrollHandDrag)
        self.setTransformationAnchor(QGraphicsView.AnchorUnderMouse)
        self.draw_mode = False
        self._start: Optional[QPointF] = None
        self._rubber: Optional[QGraphicsRectItem] = None

    def wheelEvent(self, event):
        f = 1.25 if event.angleDelta().y() > 0 else 0.8
        self.scale(f, f)

    def set_draw_mode(self, on: bool) -> None:
        self.draw_mode = on
        self.setDragMode(QGraphicsView.NoDrag if on else QGraphicsView.ScrollHandDrag)
        self.viewport().setCursor(Qt.CrossCursor if on else Qt.ArrowCursor)

    def mousePressEvent(self, event):
        if self.draw_mode and event.button() == Qt.LeftButton:
            self._start = self.mapToScene(event.position().toPoint())
            pen = QPen(Qt.white, 1, Qt.DashLine)
            pen.setCosmetic(True)
            self._rubber = self.scene().addRect(QRectF(self._start, self._start), pen)
            return
        super().mousePressEvent(event)

    def mouseMoveEvent(self, event):
        if self._rubber is not None:
            self._rubber.setRect(QRectF(self._start, self.mapToScene(event.position().toPoint())).normalized())
            return
        super().mouseMoveEvent(event)

    def mouseReleaseEvent(self, event):
        if self._rubber is not None:
            rect = self._rubber.rect()
            self.scene().removeItem(self._rubber)
            self._rubber = None
            if rect.width() >= 1 and rect.height() >= 1:
                self.drawn.emit(rect)
            return
        super().mouseReleaseEvent(event)


class MapView(QWidget):
    """An epoch's map, detections and editable plan. Signals: ``saveRequested(plan)``,
    ``exportRequested(plan)``, ``addRequested(rect)`` (a window was drawn) and ``reflectorPicked(id)``.

    The windows live in :attr:`editor` (a Qt-free :class:`app.gui.state.plan_edit.PlanEditor` with undo
    and redo); this view draws them and hands it the user's gestures."""
    saveRequested = Signal(object)
    exportRequested = Signal(object)
    addRequested = Signal(QRectF)
    reflectorPicked = Signal(str)

    COLUMNS = ["Target", "Group", "Window φ×θ [°]", "Steps φ/θ [°]", "Window points", "Target points",
               "Seconds", "Notes"]

    def __init__(self, parent=None):
        super().__init__(parent)
        self.scene = QGraphicsScene(self)
        self.view = MapGraphicsView(self.scene)
        self.view.drawn.connect(self.addRequested)
        self.scene.selectionChanged.connect(self._on_scene_selection)
        self.title = QLabel("No epoch selected")
        self.total = QLabel("")
        self.draw_btn = QPushButton("Draw window")
        self.draw_btn.setCheckable(True)
        self.draw_btn.toggled.connect(self.view.set_draw_mode)
        self.delete_btn = QPushButton("Delete window")
        self.delete_btn.clicked.connect(self.delete_selected)
        self.reset_btn = QPushButton("Revert")
        self.reset_btn.clicked.connect(self.revert)
        self.undo_btn = QPushButton("Undo")
        self.undo_btn.setToolTip("Undo the last change of the windows (Ctrl+Z)")
        self.undo_btn.clicked.connect(self.undo)
        self.redo_btn = QPushButton("Redo")
        self.redo_btn.setToolTip("Redo (Ctrl+Shift+Z)")
        self.redo_btn.clicked.connect(self.redo)
        for keys, slot in ((QKeySequence.Undo, self.undo), (QKeySequence.Redo, self.redo)):
            QShortcut(keys, self, slot, context=Qt.WidgetWithChildrenShortcut)
        self.save_btn = QPushButton("Save plan")
        self.save_btn.clicked.connect(lambda: self.saveRequested.emit(self.current_plan()))
        self.export_btn = QPushButton("Export plan JSON…")
        self.export_btn.clicked.connect(lambda: self.exportRequested.emit(self.current_plan()))
        fit = QPushButton("Show all")
        fit.clicked.connect(lambda: self.fit(everything=True))
        bar = QHBoxLayout()
        for w in (self.title, self.draw_btn, self.delete_btn, self.undo_btn, self.redo_btn, self.reset_btn,
                  self.save_btn, self.export_btn, fit):
            bar.addWidget(w)
        bar.insertStretch(1, 1)
        self.table = QTableWidget(0, len(self.COLUMNS))
        self.table.setHorizontalHeaderLabels(self.COLUMNS)
        self.table.setEditTriggers(QAbstractItemView.NoEditTriggers)
        self.table.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.table.itemSelectionChanged.connect(self._on_table_selection)
        lower = QWidget()
        ll = QVBoxLayout(lower)
        ll.setContentsMargins(0, 0, 0, 0)
        ll.addWidget(self.total)
        ll.addWidget(self.table)
        split = QSplitter(Qt.Vertical)
        split.addWidget(self.view)
        split.addWidget(lower)
        split.setStretchFactor(0, 3)
        split.setStretchFactor(1, 1)
        split.setSizes([650, 250])
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(split)
        self.label: Optional[str] = None  # the epoch shown
        self.geometry_: Optional[MapGeometry] = None
        self.preview = None
        self.items: list[RoiItem] = []
        self._syncing = False
        self.editor = PlanEditor()
        self.editor.on_change = self._editor_changed
        self._set_enabled(False)

    @property
    def plan(self) -> Optional[ScanPlan]:
        """The plan as edited (None: no plan shown)."""
        return self.editor.plan

    @property
    def stored_plan(self) -> Optional[ScanPlan]:
        return self.editor.stored

    @property
    def dirty(self) -> bool:
        """Whether the windows differ from the saved plan."""
        return self.editor.dirty

    def _set_enabled(self, on: bool) -> None:
        for b in (self.draw_btn, self.delete_btn, self.reset_btn, self.save_btn, self.export_btn):
            b.setEnabled(on)
        self.undo_btn.setEnabled(on and self.editor.can_undo)
        self.redo_btn.setEnabled(on and self.editor.can_redo)

    # ------------------------------------------------------------------ content
    def _clear_scene(self) -> None:
        self.items = []
        self.scene.blockSignals(True)  # clearing deletes the items; no selection signals about them
        self.scene.clear()
        self.scene.blockSignals(False)

    def show_message(self, text: str) -> None:
        self._clear_scene()
        self.label = None
        self.editor.load(None)  # empties the table and disables the buttons
        self.title.setText(text)
        self.total.setText("")

    def load(self, label: str, preview, plan: Optional[ScanPlan]) -> None:
        """Show an epoch's stored map preview and plan (``plan`` may be None)."""
        self._clear_scene()
        self.label = label
        rmap = preview.reflectance_map
        self.preview = preview
        self.geometry_ = g = MapGeometry(rmap.theta0_deg, rmap.phi0_deg, rmap.step_deg)
        self.scene.addPixmap(QPixmap.fromImage(map_image(rmap.max_intensity)))
        self.scene.setSceneRect(QRectF(0, 0, rmap.shape[1], rmap.shape[0]))
        matched = {m.detection: m for m in preview.identification.matches if m.detection is not None}
        for k, d in enumerate(preview.detections.detections):
            m = matched.get(k)
            colour = GROUP_COLOURS.get(m.group if m else "", GROUP_COLOURS[""])
            p = g.point_of(d.theta_deg, d.phi_deg)
            r = max(d.size_deg / g.step, 2.0)
            pen = QPen(colour, 1.5)
            pen.setCosmetic(True)
            self.scene.addItem(e := QGraphicsEllipseItem(p.x() - r, p.y() - r, 2 * r, 2 * r))
            e.setPen(pen)
            t = QGraphicsSimpleTextItem(m.id if m else "?")
            t.setBrush(QBrush(colour))
            t.setFlag(QGraphicsItem.ItemIgnoresTransformations)
            t.setPos(p.x() + r, p.y() - r - 2)
            self.scene.addItem(t)
        self.title.setText(f"Epoch {label}: {rmap.shape[1]}×{rmap.shape[0]} cells of {rmap.step_deg:.3f}°, "
                           f"{len(preview.detections.detections)} detections")
        self.editor.load(plan)  # draws the windows and enables the buttons when there is a plan
        self.fit()
        QTimer.singleShot(0, self.fit)  # again once the view has its final size

    def _editor_changed(self) -> None:
        """Draw what the editor holds: keep the items of windows that stay (a window being dragged
        is never replaced under the mouse), move those whose shape changed, add and remove the rest."""
        rois = self.editor.rois
        wanted = {r.reflector: r for r in rois}
        keep = []
        for it in self.items:
            if it.roi.reflector in wanted:
                keep.append(it)
            else:
                self.scene.removeItem(it)
        have = {it.roi.reflector: it for it in keep}
        self.items = []
        self._syncing = True
        try:
            for roi in rois:
                it = have.get(roi.reflector)
                if it is None:
                    it = RoiItem(roi, self.geometry_.rect_of(roi), self._roi_changed)
                    self.scene.addItem(it)
                elif it.roi is not roi:
                    it.roi = roi
                    if it._edges is None and not (self.scene.mouseGrabberItem() is it):
                        it.set_scene_rect(self.geometry_.rect_of(roi))
                self.items.append(it)
        finally:
            self._syncing = False
        self._refresh_table()
        self._set_enabled(self.editor.stored is not None)

    def add_roi(self, roi: RoiPlan) -> RoiItem:
        """Add a window (one undo step); returns its item."""
        self.editor.add(roi)
        return next(it for it in self.items if it.roi.reflector == roi.reflector)

    def undo(self) -> None:
        self.editor.undo()

    def redo(self) -> None:
        self.editor.redo()

    def revert(self) -> None:
        self.editor.revert()

    def fit(self, *, everything: bool = False) -> None:
        """Zoom on the selected window (when one is selected), else on all windows."""
        sel = [it for it in self.items if it.isSelected()]
        if sel and not everything:
            self._zoom_to(sel[0])
        elif self.items:
            r = self.items[0].scene_rect()
            for it in self.items[1:]:
                r = r.united(it.scene_rect())
            self.view.fitInView(r.adjusted(-r.width() * 0.1 - 20, -r.height() * 0.5 - 20, r.width() * 0.1 + 20,
                                           r.height() * 0.5 + 20), Qt.KeepAspectRatio)
        else:
            self.view.fitInView(self.scene.sceneRect(), Qt.KeepAspectRatio)

    def delete_selected(self) -> None:
        self.editor.remove([it.roi.reflector for it in self.items if it.isSelected()])

    def showEvent(self, event):
        super().showEvent(event)
        QTimer.singleShot(0, self.fit)

    def keyPressEvent(self, event):
        if event.key() in (Qt.Key_Delete, Qt.Key_Backspace):
            self.delete_selected()
            return
        super().keyPressEvent(event)

    # ------------------------------------------------------------------ live plan
    def _roi_changed(self, item: RoiItem, final: bool) -> None:
        if self.editor.stored is None or self._syncing:
            return
        # a window dragged off the sky (theta outside 0..180) keeps its last valid shape
        self.editor.reshape(item.roi.reflector, self.geometry_.window_of(item.scene_rect()), final=final)

    def current_plan(self) -> Optional[ScanPlan]:
        return self.plan

    def _refresh_table(self) -> None:
        self.table.setRowCount(len(self.items))
        for row, it in enumerate(self.items):
            r = it.roi
            w = r.window
            vals = [r.reflector, r.group, f"{w.phi_max_deg - w.phi_min_deg:.3f} × {w.theta_max_deg - w.theta_min_deg:.3f}",
                    f"{w.phi_step_deg:.4f} / {w.theta_step_deg:.4f}", f"{r.expected_points:,}",
                    f"{r.expected_target_points:,}", f"{r.expected_seconds:.1f}", "; ".join(r.notes)]
            for col, v in enumerate(vals):
                self.table.setItem(row, col, QTableWidgetItem(v))
        self.table.resizeColumnsToContents()
        if self.plan is not None:
            over = self.plan.total_seconds > self.plan.budget_seconds
            self.total.setText(f"{len(self.items)} windows, {self.plan.total_seconds / 60:.1f} min of "
                               f"{self.plan.budget_seconds / 60:.0f} min budget"
                               + (" — OVER BUDGET" if over else "") + (" (edited, not saved)" if self.dirty else ""))
            self.total.setStyleSheet("color: #d62728;" if over else "")

    def _on_scene_selection(self) -> None:
        sel = [k for k, it in enumerate(self.items) if it.isSelected()]
        if sel:
            self._syncing = True
            self.table.selectRow(sel[0])
            self._syncing = False
            self.reflectorPicked.emit(self.items[sel[0]].roi.reflector)

    def _on_table_selection(self) -> None:
        if self._syncing:
            return
        rows = {i.row() for i in self.table.selectedIndexes()}
        for k, it in enumerate(self.items):
            it.setSelected(k in rows)

    def select_reflector(self, rid: Optional[str]) -> None:
        """Select a target's window and zoom so that it shows with its surroundings."""
        for it in self.items:
            if it.roi.reflector == rid and not it.isSelected():
                self.scene.clearSelection()
                it.setSelected(True)
                self._zoom_to(it)

    def _zoom_to(self, item: "RoiItem") -> None:
        r = item.scene_rect()
        pad = max(r.width(), r.height()) * 6
        self.view.fitInView(r.adjusted(-pad, -pad, pad, pad), Qt.KeepAspectRatio)

"""The reflectance map of an epoch with its detections and the fine-scan windows, which can be moved,
resized, added and deleted; the plan's points and seconds follow live, and the plan can be saved.

The map is drawn as the report draws it: azimuth growing to the left (as the scanner sees the
scene), zenith angle growing downwards, grey intensities with the sky light blue, reference targets
cyan and measurement targets green, detection rings orange; labels sit beside their boxes on a dark
tag, above everything else, and angle ticks run along the edges.

Scene coordinates are map cells, mirrored: x = ncols - (phi - phi0) / step (azimuth, wrapping),
y = (theta - theta0) / step. What the view draws lives in a Qt-free
:class:`app.gui.state.map_state.MapState` (the preview and a :class:`PlanEditor` with undo and redo);
the view hands the editor the user's gestures.
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QBrush, QColor, QFont, QFontMetricsF, QImage, QKeySequence, QPainter, QPen, QPixmap, QShortcut
from PySide6.QtWidgets import (
    QAbstractItemView,
    QGraphicsEllipseItem,
    QGraphicsItem,
    QGraphicsRectItem,
    QGraphicsScene,
    QGraphicsView,
    QHeaderView,
    QPushButton,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QToolBar,
    QVBoxLayout,
    QWidget,
)

from app.gui.state.map_geometry import CellRect, window_of_cells
from app.gui.state.words import windows_text
from app.gui.widgets import ElidedLabel
from lidar.plan import RoiPlan, ScanPlan

#: The report's colours (lidar.figures.reflectance_map_figure): reference cyan, measurement green,
#: detection rings orange, an unidentified detection red.
GROUP_COLOURS = {"reference": QColor("#17becf"), "measurement": QColor("#2ca02c"), "": QColor("#d62728")}
DETECTION_COLOUR = QColor("#ff7f0e")
NO_RETURN = (0xdf, 0xe9, 0xf5)  # the report's light blue: no return (sky)
#: A window selected from the tree smaller than this on the screen (pixels) is zoomed on (issue 41: 7x6 px).
MIN_SHOWN_PX = 40
#: The note of a window that does not hold its whole target (the disc and its margin).
CUT_NOTE = "the window cuts the target: fewer points on it than planned"
TAG_Z, WINDOW_Z, DETECTION_Z = 30.0, 10.0, 5.0


def map_image(max_intensity: np.ndarray) -> QImage:
    """Grey image (empty cells light blue) of a (rows, cols) intensity map in [0, 1], mirrored left-right
    (azimuth grows to the left)."""
    m = np.fliplr(max_intensity)
    # matplotlib's "gray" colormap by hand (its 256 levels, floor(v * 256)): the colormap call took most of a second
    # on the interface thread for a map of millions of cells
    grey = np.minimum(np.clip(np.nan_to_num(m, nan=0.0), 0.0, 1.0) * 256.0, 255.0).astype(np.uint8)
    h, w = m.shape
    rgba = np.empty((h, w, 4), np.uint8)
    rgba[..., :3] = grey[..., None]
    rgba[..., 3] = 255
    rgba[np.isnan(m)] = (*NO_RETURN, 255)
    img = QImage(np.ascontiguousarray(rgba).data, w, h, 4 * w, QImage.Format_RGBA8888)
    return img.copy()  # own the pixels


class MapGeometry:
    """Conversions between scanner angles, map cells and (mirrored) scene coordinates of one map."""

    def __init__(self, theta0: float, phi0: float, step: float, ncols: int):
        self.theta0, self.phi0, self.step, self.ncols = theta0, phi0, step, ncols

    def _u(self, phi: float) -> float:
        return float(np.mod(phi - self.phi0, 360.0)) / self.step

    def rect_of(self, roi: RoiPlan) -> QRectF:
        return self.rect_of_window(roi.window)

    def rect_of_window(self, w) -> QRectF:
        """The scene rectangle of an angular window (an :class:`lidar.angles.AngularWindow`)."""
        width = (w.phi_max_deg - w.phi_min_deg) / self.step
        right = self.ncols - self._u(w.phi_min_deg)
        y0 = (w.theta_min_deg - self.theta0) / self.step
        return QRectF(right - width, y0, width, (w.theta_max_deg - w.theta_min_deg) / self.step)

    def cells(self, rect: QRectF) -> CellRect:
        """A scene rectangle as map cells (unmirrored, as the Qt-free code and the map's arrays count them)."""
        return CellRect(self.ncols - rect.right(), rect.top(), rect.width(), rect.height())

    def window_of(self, rect: QRectF) -> dict:
        return window_of_cells(self.cells(rect), self.theta0, self.phi0, self.step)

    def point_of(self, theta: float, phi: float) -> QPointF:
        return QPointF(self.ncols - self._u(phi), (theta - self.theta0) / self.step)

    def phi_at(self, x: float) -> float:
        return float(np.mod(self.phi0 + (self.ncols - x) * self.step, 360.0))

    def theta_at(self, y: float) -> float:
        return self.theta0 + y * self.step


class TagItem(QGraphicsItem):
    """A label on a dark tag, a fixed size on screen, beside an anchor point (``dx``, ``dy`` pixels from it;
    ``dy`` < 0 puts it above), drawn above the map's other items."""

    def __init__(self, text: str, colour: QColor, *, dx: float = 4.0, dy: float = -4.0, bold: bool = True,
                 parent: QGraphicsItem | None = None):
        super().__init__(parent)
        self.text, self.colour = text, colour
        self.font = QFont("Sans", 9, QFont.Bold if bold else QFont.Normal)
        fm = QFontMetricsF(self.font)
        w, h = fm.horizontalAdvance(text) + 6, fm.height() + 2
        # anchored at its bottom-left corner when dy < 0 (above the point), top-left otherwise
        top = dy - h if dy < 0 else dy
        self._rect = QRectF(dx, top, w, h)
        self.setFlag(QGraphicsItem.ItemIgnoresTransformations)
        self.setZValue(TAG_Z)
        self.setAcceptedMouseButtons(Qt.NoButton)

    def boundingRect(self) -> QRectF:  # noqa: N802
        return self._rect

    def paint(self, painter: QPainter, _option, _widget=None) -> None:
        painter.setPen(Qt.NoPen)
        painter.setBrush(QColor(20, 20, 24, 200))
        painter.drawRoundedRect(self._rect, 3, 3)
        painter.setPen(self.colour.lighter(130))
        painter.setFont(self.font)
        painter.drawText(self._rect, Qt.AlignCenter, self.text)


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
        self.setBrush(QBrush(QColor(colour.red(), colour.green(), colour.blue(), 50)))
        self.setFlags(QGraphicsItem.ItemIsMovable | QGraphicsItem.ItemIsSelectable
                      | QGraphicsItem.ItemSendsGeometryChanges)
        self.setAcceptHoverEvents(True)
        self.setZValue(WINDOW_Z)
        self.label = TagItem(roi.reflector, colour, dx=0.0, dy=-3.0, parent=self)  # above the box's corner
        self._edges = None
        #: The scene rectangle the window must keep holding (its target's disc and margin), or None.
        self.keep: QRectF | None = None

    def scene_rect(self) -> QRectF:
        return self.mapRectToScene(self.rect())

    def _scale(self) -> float:
        view = self.scene().views()[0] if self.scene() and self.scene().views() else None
        return max(view.transform().m11(), 1e-9) if view else 1.0

    def _edges_at(self, pos: QPointF):
        """The edges (nearest one per axis) within a few screen pixels of ``pos``.

        The handles never take more than a quarter of the window on each side: the middle of a small window
        (a few pixels on the screen) is its body, which moves it. (They took all of it: a drag meant to move a
        7x6 px window moved its corner and shrank it instead.)
        """
        r = self.rect()
        tol = min(self.HANDLE_PX / self._scale(), 0.25 * min(r.width(), r.height()))
        edges = set()
        dl, dr = abs(pos.x() - r.left()), abs(pos.x() - r.right())
        if min(dl, dr) < tol:
            edges.add("l" if dl < dr else "r")
        dt, db = abs(pos.y() - r.top()), abs(pos.y() - r.bottom())
        if min(dt, db) < tol:
            edges.add("t" if dt < db else "b")
        return edges

    def hoverMoveEvent(self, event):  # noqa: N802
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

    def mousePressEvent(self, event):  # noqa: N802
        self._edges = self._edges_at(event.pos()) or None
        if self._edges:
            event.accept()
            return
        super().mousePressEvent(event)

    def mouseMoveEvent(self, event):  # noqa: N802
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
            if self.keep is not None:  # never below the target's disc and its margin
                k = self.keep.translated(-self.pos())
                r.setLeft(min(r.left(), k.left()))
                r.setRight(max(r.right(), k.right()))
                r.setTop(min(r.top(), k.top()))
                r.setBottom(max(r.bottom(), k.bottom()))
            self.set_scene_rect(self.mapRectToScene(r))
            self.on_change(self, False)
            return
        super().mouseMoveEvent(event)

    def mouseReleaseEvent(self, event):  # noqa: N802
        self._edges = None
        super().mouseReleaseEvent(event)
        self.on_change(self, True)

    def itemChange(self, change, value):  # noqa: N802
        if change == QGraphicsItem.ItemPositionChange and self.keep is not None and not self._edges:
            value = self._holding(QPointF(value))  # a move keeps the target inside
        if change == QGraphicsItem.ItemPositionHasChanged and self.scene() is not None and not self._edges:
            self.on_change(self, False)
        return super().itemChange(change, value)

    def _holding(self, pos: QPointF) -> QPointF:
        """``pos`` moved the least for the window there to hold :attr:`keep` (an axis it cannot hold: as it is)."""
        k, w, h = self.keep, self.rect().width(), self.rect().height()
        x, y = pos.x(), pos.y()
        if w >= k.width():
            x = min(max(x, k.right() - w), k.left())
        if h >= k.height():
            y = min(max(y, k.bottom() - h), k.top())
        return QPointF(x, y)

    def set_scene_rect(self, rect: QRectF) -> None:
        self.prepareGeometryChange()
        self.setPos(rect.topLeft())
        self.setRect(QRectF(0, 0, rect.width(), rect.height()))


def nice_step(span: float, pixels: float, *, every_px: float = 90.0) -> float:
    """A round tick spacing (1, 2 or 5 × 10^k degrees) giving a tick about every ``every_px`` pixels."""
    if span <= 0 or pixels <= 0:
        return 1.0
    raw = span * every_px / pixels
    mag = 10.0 ** math.floor(math.log10(raw))
    return next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)


class MapGraphicsView(QGraphicsView):
    """Zoom with the wheel, pan by dragging the background; in draw mode a drag draws a new window.
    Azimuth and zenith-angle ticks run along the bottom and left edges."""
    drawn = Signal(QRectF)
    RULER_PX = 18

    def __init__(self, scene, parent=None):
        super().__init__(scene, parent)
        self.setRenderHint(QPainter.Antialiasing)
        self.setDragMode(QGraphicsView.ScrollHandDrag)
        self.setTransformationAnchor(QGraphicsView.AnchorUnderMouse)
        self.setViewportUpdateMode(QGraphicsView.FullViewportUpdate)  # the rulers follow every scroll
        self.setMinimumSize(200, 150)
        self.draw_mode = False
        self.geometry_: MapGeometry | None = None
        self._start: QPointF | None = None
        self._rubber: QGraphicsRectItem | None = None

    def wheelEvent(self, event):  # noqa: N802
        f = 1.25 if event.angleDelta().y() > 0 else 0.8
        self.scale(f, f)

    def set_draw_mode(self, on: bool) -> None:
        self.draw_mode = on
        self.setDragMode(QGraphicsView.NoDrag if on else QGraphicsView.ScrollHandDrag)
        self.viewport().setCursor(Qt.CrossCursor if on else Qt.ArrowCursor)

    def mousePressEvent(self, event):  # noqa: N802
        if self.draw_mode and event.button() == Qt.LeftButton:
            self._start = self.mapToScene(event.position().toPoint())
            pen = QPen(Qt.white, 1, Qt.DashLine)
            pen.setCosmetic(True)
            self._rubber = self.scene().addRect(QRectF(self._start, self._start), pen)
            return
        super().mousePressEvent(event)

    def mouseMoveEvent(self, event):  # noqa: N802
        if self._rubber is not None:
            self._rubber.setRect(QRectF(self._start, self.mapToScene(event.position().toPoint())).normalized())
            return
        super().mouseMoveEvent(event)

    def mouseReleaseEvent(self, event):  # noqa: N802
        if self._rubber is not None:
            rect = self._rubber.rect()
            self.scene().removeItem(self._rubber)
            self._rubber = None
            if rect.width() >= 1 and rect.height() >= 1:
                self.drawn.emit(rect)
            return
        super().mouseReleaseEvent(event)

    def drawForeground(self, painter: QPainter, _rect) -> None:  # noqa: N802
        g = self.geometry_
        if g is None:
            return
        vp = self.viewport().rect()
        tl, br = self.mapToScene(vp.topLeft()), self.mapToScene(vp.bottomRight())
        painter.save()
        painter.resetTransform()
        font = QFont("Sans", 8)
        painter.setFont(font)
        fm = QFontMetricsF(font)
        band = QColor(255, 255, 255, 215)
        painter.fillRect(QRectF(0, vp.height() - self.RULER_PX, vp.width(), self.RULER_PX), band)
        painter.fillRect(QRectF(0, 0, 44, vp.height() - self.RULER_PX), band)
        painter.setPen(QColor(30, 30, 30))
        # azimuth along the bottom: it grows to the left
        span_deg = (br.x() - tl.x()) * g.step
        step = nice_step(span_deg, vp.width())
        phi_left, phi_right = g.phi0 + (g.ncols - tl.x()) * g.step, g.phi0 + (g.ncols - br.x()) * g.step
        k = math.ceil(phi_right / step)
        while k * step <= phi_left:
            phi = k * step
            x = self.mapFromScene(QPointF(g.ncols - (phi - g.phi0) / g.step, 0)).x()
            k += 1
            if x < 60:  # the corner holds the axis names
                continue
            painter.drawLine(QPointF(x, vp.height() - self.RULER_PX), QPointF(x, vp.height() - self.RULER_PX + 4))
            text = f"{phi % 360.0:g}°"
            painter.drawText(QPointF(x - fm.horizontalAdvance(text) / 2, vp.height() - 3), text)
        painter.fillRect(QRectF(0, vp.height() - self.RULER_PX, 44, self.RULER_PX), band)
        painter.drawText(QPointF(2, vp.height() - 3), "θ↓ φ←")
        # zenith angle down the left edge
        span_deg = (br.y() - tl.y()) * g.step
        step = nice_step(span_deg, vp.height(), every_px=60.0)
        t_top, t_bottom = g.theta_at(tl.y()), g.theta_at(br.y())
        k = math.ceil(t_top / step)
        while k * step <= t_bottom:
            y = self.mapFromScene(QPointF(0, (k * step - g.theta0) / g.step)).y()
            if y < vp.height() - self.RULER_PX - 4:
                painter.drawLine(QPointF(40, y), QPointF(44, y))
                painter.drawText(QPointF(2, y + fm.ascent() / 2 - 1), f"{k * step:g}°")
            k += 1
        painter.restore()


class NotesTable(QTableWidget):
    """A table whose rows grow to show their wrapped notes whenever its width changes."""

    def resizeEvent(self, event):  # noqa: N802
        super().resizeEvent(event)
        QTimer.singleShot(0, self.resizeRowsToContents)


class MapView(QWidget):
    """An epoch's map, detections and editable plan, drawn from a :class:`app.gui.state.map_state.MapState`.

    Signals: ``saveRequested(plan)``, ``exportRequested(plan)``, ``addRequested(cells)`` (a window was
    drawn; a :class:`app.gui.state.map_geometry.CellRect` in map cells) and ``reflectorPicked(id)``.
    """
    saveRequested = Signal(object)
    exportRequested = Signal(object)
    addRequested = Signal(object)
    reflectorPicked = Signal(str)

    COLUMNS = ["Target", "On", "Window\nφ×θ [°]", "Steps\nφ/θ [°]", "Window\npoints", "Target\npoints",
               "Seconds", "Notes"]

    def __init__(self, map_state, parent=None):
        super().__init__(parent)
        self.state = map_state
        self.editor = map_state.editor
        self.scene = QGraphicsScene(self)
        self.view = MapGraphicsView(self.scene)
        self.view.drawn.connect(self._drawn)
        self.scene.selectionChanged.connect(self._on_scene_selection)
        self.title = ElidedLabel("No epoch selected")
        self.total = ElidedLabel("")
        self.draw_btn = QPushButton("Draw window")
        self.draw_btn.setCheckable(True)
        self.draw_btn.setToolTip("Drag on the map to add a window for a target that has none")
        self.draw_btn.toggled.connect(self.view.set_draw_mode)
        self.delete_btn = QPushButton("Delete")
        self.delete_btn.setToolTip("Delete the selected window (Delete key)")
        self.delete_btn.clicked.connect(self.delete_selected)
        self.reset_btn = QPushButton("Revert")
        self.reset_btn.setToolTip("Back to the saved plan")
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
        self.save_btn.setToolTip("Store the edited plan in the campaign (processing measures the epoch with it)")
        self.save_btn.clicked.connect(lambda: self.saveRequested.emit(self.current_plan()))
        self.export_btn = QPushButton("Export plan JSON…")
        self.export_btn.setToolTip("Write the plan for the scanner")
        self.export_btn.clicked.connect(lambda: self.exportRequested.emit(self.current_plan()))
        self.fit_btn = QPushButton("Show all")
        self.fit_btn.setToolTip("Zoom out on the whole bridge")
        self.fit_btn.clicked.connect(lambda: self.fit(everything=True))
        bar = QToolBar()
        bar.setStyleSheet("QToolBar { border: 0; spacing: 3px; }")
        for w in (self.draw_btn, self.delete_btn, self.undo_btn, self.redo_btn, self.reset_btn, self.save_btn,
                  self.export_btn, self.fit_btn):
            bar.addWidget(w)
        self.bar = bar
        self.table = NotesTable(0, len(self.COLUMNS))
        self.table.setHorizontalHeaderLabels(self.COLUMNS)
        self.table.setEditTriggers(QAbstractItemView.NoEditTriggers)
        self.table.setSelectionBehavior(QAbstractItemView.SelectRows)
        self.table.setWordWrap(True)
        self.table.setTextElideMode(Qt.ElideNone)
        header = self.table.horizontalHeader()
        for col in range(len(self.COLUMNS) - 1):
            header.setSectionResizeMode(col, QHeaderView.ResizeToContents)
        header.setSectionResizeMode(len(self.COLUMNS) - 1, QHeaderView.Stretch)  # the notes take what is left
        header.setMinimumSectionSize(40)
        self.table.verticalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
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
        split.setSizes([450, 180])
        split.setChildrenCollapsible(False)
        self.splitter = split
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.title)
        lay.addWidget(bar)
        lay.addWidget(split, 1)
        self.geometry_: MapGeometry | None = None
        self.items: list[RoiItem] = []
        self._syncing = False
        self._selecting = False
        map_state.preview_changed.connect(self._draw_preview)
        map_state.message.connect(self.show_message)
        self.editor.changed.connect(self._editor_changed)
        self._set_enabled(False)

    @property
    def label(self) -> str | None:
        """The epoch shown."""
        return self.state.label

    @property
    def preview(self):
        return self.state.preview

    @property
    def plan(self) -> ScanPlan | None:
        """The plan as edited (None: no plan shown)."""
        return self.editor.plan

    @property
    def dirty(self) -> bool:
        """Whether the windows differ from the saved plan."""
        return self.editor.dirty

    def _set_enabled(self, on: bool) -> None:
        for b in (self.draw_btn, self.delete_btn, self.reset_btn, self.save_btn, self.export_btn):
            b.setEnabled(on)
        self.undo_btn.setEnabled(on and self.editor.can_undo)
        self.redo_btn.setEnabled(on and self.editor.can_redo)

    # ------------------------------------------------------------------ what the state says
    def _clear_scene(self) -> None:
        self.items = []
        self.scene.blockSignals(True)  # clearing deletes the items; no selection signals about them
        self.scene.clear()
        self.scene.blockSignals(False)

    def show_message(self, text: str) -> None:
        self._clear_scene()
        self.geometry_ = self.view.geometry_ = None
        self.title.setText(text)
        self.total.setText("")

    def show_selection(self, sel) -> None:
        """Select the selected target's window (an :class:`app.gui.state.app_state.Selection`)."""
        if sel.reflector:
            self.select_reflector(sel.reflector)

    def _draw_preview(self, label: str, preview, plan) -> None:
        """A new epoch's map: the image, its detections (the windows follow from the editor)."""
        self._clear_scene()
        rmap = preview.reflectance_map
        rows, cols = rmap.shape
        self.geometry_ = self.view.geometry_ = g = MapGeometry(rmap.theta0_deg, rmap.phi0_deg, rmap.step_deg, cols)
        self.scene.addPixmap(QPixmap.fromImage(map_image(rmap.max_intensity)))
        self.scene.setSceneRect(QRectF(0, 0, cols, rows))
        planned = {r.reflector for r in plan.rois} if plan is not None else set()
        matched = {m.detection: m for m in preview.identification.matches if m.detection is not None}
        self._bridge = QRectF()
        for k, d in enumerate(preview.detections.detections):
            m = matched.get(k)
            p = g.point_of(d.theta_deg, d.phi_deg)
            r = max(d.size_deg / g.step, 2.0)
            pen = QPen(DETECTION_COLOUR, 1.5)
            pen.setCosmetic(True)
            self.scene.addItem(e := QGraphicsEllipseItem(p.x() - r, p.y() - r, 2 * r, 2 * r))
            e.setPen(pen)
            e.setZValue(DETECTION_Z)
            if m is not None:
                self._bridge = self._bridge.united(QRectF(p.x() - r, p.y() - r, 2 * r, 2 * r))
            if m is None or m.id not in planned:  # a planned target is named on its window
                tag = TagItem(m.id if m else "?", GROUP_COLOURS.get(m.group if m else "", GROUP_COLOURS[""]),
                              dx=6.0, dy=2.0, bold=m is not None)
                tag.setPos(p.x() + r, p.y())
                self.scene.addItem(tag)
        self.title.setText(f"Epoch {label}: {cols}×{rows} cells of {rmap.step_deg:.3f}°, "
                           f"{len(preview.detections.detections)} detections; azimuth grows to the left, as the "
                           "scanner sees the bridge")
        QTimer.singleShot(0, lambda: self.fit(everything=True))  # once the view has its final size

    def _editor_changed(self) -> None:
        """Draw what the editor holds: keep the items of windows that stay (a window being dragged
        is never replaced under the mouse), move those whose shape changed, add and remove the rest."""
        rois = self.editor.rois if self.geometry_ is not None else ()
        wanted = {r.reflector: r for r in rois}
        keep = []
        for it in self.items:
            if it.roi.reflector in wanted:
                keep.append(it)
            elif it.scene() is self.scene:
                self.scene.removeItem(it)
        have = {it.roi.reflector: it for it in keep}
        self.items = []
        self._syncing = True
        try:
            for roi in rois:
                it = have.get(roi.reflector)
                if it is None:
                    it = RoiItem(roi, self.geometry_.rect_of(roi), self._roi_changed)
                    ext = self.state.extent(roi.reflector)
                    it.keep = None if ext is None else self.geometry_.rect_of_window(ext)
                    self.scene.addItem(it)
                elif it.roi is not roi:
                    it.roi = roi
                    if it._edges is None and not (self.scene.mouseGrabberItem() is it):
                        it.set_scene_rect(self.geometry_.rect_of(roi))
                self.items.append(it)
        finally:
            self._syncing = False
        self._refresh_table()
        QTimer.singleShot(0, self.table.resizeRowsToContents)  # once the notes column has its width
        self._set_enabled(self.editor.stored is not None and self.geometry_ is not None)

    # ------------------------------------------------------------------ gestures
    def _drawn(self, rect: QRectF) -> None:
        self.draw_btn.setChecked(False)
        if self.geometry_ is not None:
            self.addRequested.emit(self.geometry_.cells(rect))

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

    def bridge_rect(self) -> QRectF:
        """The part of the map holding the bridge: every window and identified target, with a margin."""
        r = QRectF(getattr(self, "_bridge", QRectF()))
        for it in self.items:
            r = r.united(it.scene_rect())
        if r.isEmpty():
            return self.scene.sceneRect()
        pad_x, pad_y = max(r.width() * 0.08, 15.0), max(r.height() * 0.25, 15.0)
        return r.adjusted(-pad_x, -pad_y, pad_x, pad_y).intersected(self.scene.sceneRect())

    def fit(self, *, everything: bool = False) -> None:
        """Zoom on the whole bridge (``everything``), or keep the view when the user has zoomed in."""
        if self.geometry_ is None:
            return
        if everything or not getattr(self, "_fitted", False):
            self.view.fitInView(self.bridge_rect(), Qt.KeepAspectRatio)
            self._fitted = True

    def delete_selected(self) -> None:
        self.editor.remove([it.roi.reflector for it in self.items if it.isSelected()])

    def showEvent(self, event):  # noqa: N802
        super().showEvent(event)
        QTimer.singleShot(0, lambda: self.fit(everything=True))

    def keyPressEvent(self, event):  # noqa: N802
        if event.key() in (Qt.Key_Delete, Qt.Key_Backspace):
            self.delete_selected()
            return
        super().keyPressEvent(event)

    # ------------------------------------------------------------------ live plan
    def _roi_changed(self, item: RoiItem, final: bool) -> None:
        if self.editor.stored is None or self._syncing or self.geometry_ is None:
            return
        # a window dragged off the sky (theta outside 0..180) keeps its last valid shape
        self.editor.reshape(item.roi.reflector, self.geometry_.window_of(item.scene_rect()), final=final)

    def current_plan(self) -> ScanPlan | None:
        return self.plan

    def _refresh_table(self) -> None:
        self.table.setRowCount(len(self.items))
        cut = {r.reflector for r in self.state.cut_targets(self.plan)}
        for row, it in enumerate(self.items):
            r = it.roi
            w = r.window
            notes = ((CUT_NOTE,) if r.reflector in cut else ()) + r.notes
            points = f"< {r.expected_target_points:,}" if r.reflector in cut else f"{r.expected_target_points:,}"
            vals = [r.reflector, "pier" if r.group == "reference" else "deck",
                    f"{w.phi_max_deg - w.phi_min_deg:.3f} × {w.theta_max_deg - w.theta_min_deg:.3f}",
                    f"{w.phi_step_deg:.4f} / {w.theta_step_deg:.4f}", f"{r.expected_points:,}",
                    points, f"{r.expected_seconds:.1f}", "; ".join(notes) or "–"]
            colour = QColor("#d62728") if r.reflector in cut else None
            for col, v in enumerate(vals):
                # only the cells that changed: every new cell makes the table measure its columns and rows again
                # (they fit their contents), which took most of a second on each step of a drag
                old = self.table.item(row, col)
                if old is not None and old.text() == v and (old.data(Qt.UserRole) == (colour is not None)):
                    continue
                item = QTableWidgetItem(v)
                item.setToolTip(v)
                item.setData(Qt.UserRole, colour is not None)
                if colour is not None:
                    item.setForeground(colour)
                self.table.setItem(row, col, item)
        if self.plan is not None:
            over = self.plan.total_seconds > self.plan.budget_seconds
            self.total.setText(f"{windows_text(self.plan.rois)}, {self.plan.total_seconds / 60:.1f} min of "
                               f"{self.plan.budget_seconds / 60:.0f} min budget"
                               + (" — OVER BUDGET" if over else "") + (" (edited, not saved)" if self.dirty else ""))
            self.total.setStyleSheet("color: #d62728;" if over else "")
        else:
            self.total.setText("")

    def _on_scene_selection(self) -> None:
        sel = [k for k, it in enumerate(self.items) if it.isSelected()]
        if sel:
            was, self._syncing = self._syncing, True
            self.table.selectRow(sel[0])
            self._syncing = was
            if not self._selecting:  # the user's pick (not the selection shown from the state)
                self.reflectorPicked.emit(self.items[sel[0]].roi.reflector)

    def _on_table_selection(self) -> None:
        if self._syncing:
            return
        rows = {i.row() for i in self.table.selectedIndexes()}
        for k, it in enumerate(self.items):
            it.setSelected(k in rows)

    def select_reflector(self, rid: str | None) -> None:
        """Select a target's window and bring it into view, zoomed on it when it is too small on the screen to be
        seen or edited (below :data:`MIN_SHOWN_PX`); not a user's pick, so it is not reported back
        (``reflectorPicked``)."""
        it = next((it for it in self.items if it.roi.reflector == rid), None)
        if it is None or it.isSelected():
            return
        self._selecting = True
        try:
            self.scene.clearSelection()
            it.setSelected(True)
        finally:
            self._selecting = False
        shown = self.view.mapFromScene(it.scene_rect()).boundingRect()
        if min(shown.width(), shown.height()) < MIN_SHOWN_PX:
            self.zoom_to(rid)
        else:
            self.view.ensureVisible(it, 40, 40)

    def zoom_to(self, rid: str) -> None:
        """Zoom on a target's window with its surroundings."""
        for it in self.items:
            if it.roi.reflector == rid:
                r = it.scene_rect()
                pad = max(r.width(), r.height()) * 3
                self.view.fitInView(r.adjusted(-pad, -pad, pad, pad), Qt.KeepAspectRatio)

"""The 3-D view (pyvista in Qt): an epoch's scan coloured by intensity, or its change against the baseline,
with the targets as labelled markers; picking near a marker selects that target everywhere.

The view renders on demand only (when its content, camera or size changes): pyvistaqt's automatic
render timer is off, because under software OpenGL each render of a large cloud takes a good part of
a second and the timer would keep the whole window busy. Clouds above the point budget are drawn
thinned (:mod:`app.gui.state.cloud_display`), with a level of detail: fewer points still while the
view moves. The change colours are symmetric about zero and reach a robust percentile of the change
on the deck and piers; the legend says so.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtCore import QTimer, Signal
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from app.gui.state.cloud_display import INTERACTIVE_POINTS, budget_indices


def opengl_available() -> bool:
    """False on Qt's offscreen platform, where VTK cannot get an OpenGL window."""
    return QGuiApplication.platformName() not in ("offscreen", "minimal")


def with_interactive_lod(plotter, actor, points, *, max_points: int = INTERACTIVE_POINTS, keep=None):
    """Replace ``actor`` (a point cloud) by a level-of-detail actor with a decimated copy for interaction.

    ``keep``: the indices of that copy, prepared in the worker (by default every n-th point within ``max_points``).
    """
    # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
    import pyvista as pv
    from vtkmodules.vtkRenderingLOD import vtkLODActor  # not "import vtk": it loads every VTK module (seconds)

    n = points.n_points
    if keep is None:
        if n <= max_points:
            return actor
        keep = budget_indices(n, max_points)
    sub = pv.PolyData(np.asarray(points.points)[keep].copy())
    for name in points.point_data.keys():
        sub.point_data[name] = np.asarray(points.point_data[name])[keep]
    coarse = actor.GetMapper().NewInstance()  # a mapper of the same kind
    coarse.ShallowCopy(actor.GetMapper())
    coarse.SetInputData(sub)
    lod = vtkLODActor()
    lod.SetMapper(actor.GetMapper())
    lod.SetProperty(actor.GetProperty())
    lod.AddLODMapper(coarse)
    plotter.remove_actor(actor, render=False)
    plotter.add_actor(lod, name="cloud", reset_camera=False, render=False)
    return lod


class CloudView(QWidget):
    """Signals: ``targetPicked(id)``; ``loadRequested(mode)`` with mode ``intensity`` or ``change``."""
    targetPicked = Signal(str)
    loadRequested = Signal(str)

    MODES = (("intensity", "scan coloured by intensity"), ("change", "change against the baseline (M3C2)"))

    def __init__(self, parent=None):
        super().__init__(parent)
        self.info = QLabel("Select an epoch and press Show.")
        self.info.setWordWrap(True)
        self.mode = QComboBox()
        for key, text in self.MODES:
            self.mode.addItem(text, key)
        self.mode.setSizeAdjustPolicy(QComboBox.AdjustToContents)
        self.show_btn = QPushButton("Show")
        self.show_btn.clicked.connect(lambda: self.loadRequested.emit(self.mode.currentData()))
        bar = QHBoxLayout()
        bar.addWidget(self.mode)
        bar.addWidget(self.show_btn)
        bar.addWidget(self.info, 1)
        self.lay = QVBoxLayout(self)
        self.lay.addLayout(bar)
        self.plotter = None
        self.cloud = None
        self.prepared = None  # the PreparedCloud drawn
        self.scale = None  # the change cloud's colour scale
        self.offset = np.zeros(3)  # subtracted from the drawn points (float32 keeps millimetres near the bridge)
        self.actor = None
        self.drawn_points = 0
        self.selected = None
        if not opengl_available():
            msg = QLabel("The 3-D view needs a display with OpenGL (it is not available on this platform).")
            msg.setWordWrap(True)
            self.lay.addWidget(msg, 1)
            self.show_btn.setEnabled(False)

    def _ensure_plotter(self):
        if self.plotter is None:
            # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
            from pyvistaqt import QtInteractor

            # auto_update=False: no render timer; VTK renders when the view is touched, we when it changes
            self.plotter = QtInteractor(self, auto_update=False)
            self.plotter.set_background("#1e1e24")
            self.lay.addWidget(self.plotter.interactor, 1)
            self.plotter.enable_point_picking(callback=self._picked, show_message=False, show_point=False,
                                              left_clicking=False, use_picker=True)
        return self.plotter

    def showEvent(self, event):  # noqa: N802
        # the 3-D widget is made (and laid out) when the tab is first shown, with nothing to draw yet: made when the
        # first cloud arrives, it was painted at several sizes in a row, each paint drawing the whole cloud
        super().showEvent(event)
        if self.plotter is None and self.show_btn.isEnabled():
            QTimer.singleShot(0, self._ensure_plotter)

    def show_message(self, text: str) -> None:
        self.info.setText(text)
        if self.plotter is not None and self.cloud is not None:
            self.cloud = None
            self.plotter.clear()
            self.plotter.render()

    def show_selection(self, sel) -> None:
        """Highlight the selected target (an :class:`app.gui.state.app_state.Selection`)."""
        if sel.reflector != self.selected:
            self.select_target(sel.reflector)

    def set_cloud(self, prepared) -> None:
        """Draw a :class:`app.gui.state.cloud_display.PreparedCloud` (thinned and prepared in the worker).

        Only the hand-over to VTK runs here, in two turns of the event loop (the actors, then the first
        frame), so that neither holds the interface for long.
        """
        # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
        import pyvista as pv

        cloud = prepared.cloud
        self.cloud, self.prepared = cloud, prepared
        p = self._ensure_plotter()
        p.clear()
        change = prepared.change
        self.mode.setCurrentIndex(1 if change else 0)
        self.offset = prepared.offset
        self.drawn_points = prepared.drawn
        pts = pv.PolyData(prepared.xyz)
        pts[cloud.value_name] = prepared.values
        # no bar title: the unit is on every tick label and the scale is explained in the corner (a title
        # over a horizontal bar's labels overlaps them)
        bar = dict(title=" ", vertical=False, position_x=0.3, position_y=0.02, width=0.4, height=0.07,
                   label_font_size=11, n_labels=5, fmt="%+.1f mm" if change else "%.2f", color="white")
        self.scale = prepared.scale
        if not change:
            actor = p.add_points(pts, scalars=cloud.value_name, cmap="cividis", point_size=2, clim=prepared.clim,
                                 scalar_bar_args=bar, render=False,
                                 reset_camera=False)
            legend = "colours: intensity, from its 1st to its 99.5th percentile"
        else:  # signed change: diverging colours, symmetric about zero, scaled on the structure
            actor = p.add_points(pts, scalars=cloud.value_name, cmap="RdBu", point_size=4, clim=prepared.clim,
                                 nan_color="grey", scalar_bar_args=bar, render=False,
                                 reset_camera=False)
            legend = "M3C2 change, red negative, blue positive; " + self.scale.legend + "; grey: no value"
        p.add_text(legend, position="upper_left", font_size=10, color="white", name="legend", render=False)
        self.actor = with_interactive_lod(p, actor, pts, keep=prepared.lod) if prepared.lod is not None else actor
        self._draw_markers()
        # oblique, from the scanner's side, z up; it resets the camera to the cloud (Plotter.reset_camera would draw)
        p.view_vector((-0.45, -1.0, 0.35), viewup=(0, 0, 1), render=False)
        QTimer.singleShot(0, self._first_frame)
        thinned = "" if prepared.drawn == cloud.n_total else \
            f" ({prepared.drawn:,} drawn, {INTERACTIVE_POINTS:,} while the view moves)"
        self.info.setText(f"{len(cloud.xyz):,} of {cloud.n_total:,} points shown{thinned}; {cloud.frame}. "
                          "Drag to turn, wheel to zoom, right-click near a target to select it.")

    def _first_frame(self) -> None:
        # one frame, drawn when Qt paints the widget next (a render() here and the paint of a newly shown view
        # drew it twice in a row)
        if self.plotter is not None:
            self.plotter._rendered = True  # pyvista's "has been drawn" (what render() sets) for its later calls
            self.plotter.interactor.update()

    def _draw_markers(self) -> None:
        # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
        import pyvista as pv

        cloud, p = self.cloud, self.plotter
        if cloud is None or not len(cloud.marker_xyz):
            return
        xyz = self.prepared.markers
        for name in ("markers", "markers_sel", "labels"):
            p.remove_actor(name, render=False)
        sel = [k for k, i in enumerate(cloud.marker_ids) if i == self.selected]
        rest = [k for k in range(len(xyz)) if k not in sel]
        if rest:
            p.add_mesh(pv.PolyData(xyz[rest]).glyph(geom=pv.Sphere(radius=0.12), scale=False, orient=False),
                       color="#ff5555", name="markers", render=False, reset_camera=False)
        if sel:
            p.add_mesh(pv.PolyData(xyz[sel]).glyph(geom=pv.Sphere(radius=0.2), scale=False, orient=False),
                       color="yellow", name="markers_sel", render=False, reset_camera=False)
        p.add_point_labels(xyz, list(cloud.marker_ids), font_size=14, text_color="white", shape_opacity=0.4,
                           name="labels", always_visible=True, render=False, reset_camera=False)

    def _picked(self, point) -> None:
        if self.cloud is None or not len(self.cloud.marker_xyz):
            return
        d = np.linalg.norm(self.cloud.marker_xyz - self.offset - np.asarray(point), axis=1)
        k = int(np.argmin(d))
        if d[k] < 1.0:
            self.targetPicked.emit(self.cloud.marker_ids[k])

    def pick_target(self, rid: str) -> None:
        """Programmatic pick (tests): as if the user picked at the marker."""
        k = list(self.cloud.marker_ids).index(rid)
        self._picked(self.cloud.marker_xyz[k] - self.offset)

    def select_target(self, rid) -> None:
        self.selected = rid
        if self.plotter is not None and self.cloud is not None:
            self._draw_markers()
            self.plotter.render()

    def close_plotter(self) -> None:
        if self.plotter is not None:
            self.plotter.close()
            self.plotter = None

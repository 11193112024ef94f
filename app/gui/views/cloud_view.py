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
from PySide6.QtCore import Signal
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from app.gui.state.cloud_display import INTERACTIVE_POINTS, POINT_BUDGET, budget_indices, change_scale


def opengl_available() -> bool:
    """False on Qt's offscreen platform, where VTK cannot get an OpenGL window."""
    return QGuiApplication.platformName() not in ("offscreen", "minimal")


def with_interactive_lod(plotter, actor, points, *, max_points: int = INTERACTIVE_POINTS):
    """Replace ``actor`` (a point cloud) by a level-of-detail actor with a decimated copy for interaction."""
    # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
    import pyvista as pv
    import vtk

    n = points.n_points
    if n <= max_points:
        return actor
    keep = budget_indices(n, max_points)
    sub = pv.PolyData(np.asarray(points.points)[keep].copy())
    for name in points.point_data.keys():
        sub.point_data[name] = np.asarray(points.point_data[name])[keep]
    coarse = vtk.vtkPolyDataMapper()
    coarse.ShallowCopy(actor.GetMapper())
    coarse.SetInputData(sub)
    lod = vtk.vtkLODActor()
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

    def set_cloud(self, cloud) -> None:
        """Draw a :class:`projects.outputs.inspection.DisplayCloud`."""
        # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
        import pyvista as pv

        self.cloud = cloud
        p = self._ensure_plotter()
        p.clear()
        change = cloud.value_name != "intensity"
        self.mode.setCurrentIndex(1 if change else 0)
        self.offset = np.median(cloud.xyz, axis=0) if len(cloud.xyz) else np.zeros(3)
        keep = budget_indices(len(cloud.xyz), POINT_BUDGET)
        self.drawn_points = len(keep)
        pts = pv.PolyData((cloud.xyz[keep] - self.offset).astype(np.float32))
        pts[cloud.value_name] = cloud.values[keep]
        # no bar title: the unit is on every tick label and the scale is explained in the corner (a title
        # over a horizontal bar's labels overlaps them)
        bar = dict(title=" ", vertical=False, position_x=0.3, position_y=0.02, width=0.4, height=0.07,
                   label_font_size=11, n_labels=5, fmt="%+.1f mm" if change else "%.2f", color="white")
        if not change:
            lo, hi = np.nanpercentile(cloud.values, [1, 99.5]) if len(cloud.values) else (0, 1)
            self.scale = None
            actor = p.add_points(pts, scalars=cloud.value_name, cmap="cividis", point_size=2,
                                 clim=(lo, max(hi, lo + 1e-3)), scalar_bar_args=bar, render=False)
            legend = "colours: intensity, from its 1st to its 99.5th percentile"
        else:  # signed change: diverging colours, symmetric about zero, scaled on the structure
            self.scale = change_scale(cloud.xyz, cloud.values, cloud.marker_xyz)
            lim = self.scale.limit
            actor = p.add_points(pts, scalars=cloud.value_name, cmap="RdBu", point_size=4, clim=(-lim, lim),
                                 nan_color="grey", scalar_bar_args=bar, render=False)
            legend = "M3C2 change, red negative, blue positive; " + self.scale.legend + "; grey: no value"
        p.add_text(legend, position="upper_left", font_size=10, color="white", name="legend")
        self.actor = with_interactive_lod(p, actor, pts)
        self._draw_markers()
        p.view_vector((-0.45, -1.0, 0.35), viewup=(0, 0, 1))  # oblique, from the scanner's side, z up
        p.reset_camera(render=False)
        p.render()
        thinned = "" if self.drawn_points == len(cloud.xyz) else \
            f" ({self.drawn_points:,} drawn, fewer while the view moves)"
        self.info.setText(f"{len(cloud.xyz):,} of {cloud.n_total:,} points shown{thinned}; {cloud.frame}. "
                          "Drag to turn, wheel to zoom, right-click near a target to select it.")

    def _draw_markers(self) -> None:
        # local: VTK (pyvista, pyvistaqt) costs the application 1-1.8 s of start-up until a 3-D view is opened (measured)
        import pyvista as pv

        cloud, p = self.cloud, self.plotter
        if cloud is None or not len(cloud.marker_xyz):
            return
        xyz = cloud.marker_xyz - self.offset
        for name in ("markers", "markers_sel", "labels"):
            p.remove_actor(name, render=False)
        sel = [k for k, i in enumerate(cloud.marker_ids) if i == self.selected]
        rest = [k for k in range(len(xyz)) if k not in sel]
        if rest:
            p.add_mesh(pv.PolyData(xyz[rest]).glyph(geom=pv.Sphere(radius=0.12), scale=False, orient=False),
                       color="#ff5555", name="markers", render=False)
        if sel:
            p.add_mesh(pv.PolyData(xyz[sel]).glyph(geom=pv.Sphere(radius=0.2), scale=False, orient=False),
                       color="yellow", name="markers_sel", render=False)
        p.add_point_labels(xyz, list(cloud.marker_ids), font_size=14, text_color="white", shape_opacity=0.4,
                           name="labels", always_visible=True, render=False)

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

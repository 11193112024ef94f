"""The 3-D view (pyvista in Qt): an epoch's scan coloured by intensity, or its change against the baseline,
with the targets as labelled markers; picking near a marker selects that target everywhere.

Large clouds are decimated for display only, and drawn with two levels of detail: every displayed
point when the view is still, a tenth of them or fewer while it is being rotated or zoomed (VTK
picks the level from the time a frame may take); the computations use every point.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtCore import Signal
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget


def opengl_available() -> bool:
    """False on Qt's offscreen platform, where VTK cannot get an OpenGL window."""
    return QGuiApplication.platformName() not in ("offscreen", "minimal")


#: Points drawn while the view moves; more are drawn only when it is still.
INTERACTIVE_POINTS = 150_000


def with_interactive_lod(plotter, actor, points, *, max_points: int = INTERACTIVE_POINTS):
    """Replace ``actor`` (a point cloud) by a level-of-detail actor with a decimated copy for interaction."""
    import pyvista as pv
    import vtk

    n = points.n_points
    if n <= max_points:
        return actor
    step = int(np.ceil(n / max_points))
    sub = pv.PolyData(np.asarray(points.points)[::step].copy())
    for name in points.point_data.keys():
        sub.point_data[name] = np.asarray(points.point_data[name])[::step]
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

    def __init__(self, parent=None):
        super().__init__(parent)
        self.info = QLabel("Select an epoch and press Show.")
        self.info.setWordWrap(True)
        self.mode = QComboBox()
        self.mode.addItems(["scan coloured by intensity", "change against the baseline (M3C2)"])
        self.show_btn = QPushButton("Show")
        self.show_btn.clicked.connect(lambda: self.loadRequested.emit(
            "intensity" if self.mode.currentIndex() == 0 else "change"))
        bar = QHBoxLayout()
        bar.addWidget(self.mode)
        bar.addWidget(self.show_btn)
        bar.addWidget(self.info, 1)
        self.lay = QVBoxLayout(self)
        self.lay.addLayout(bar)
        self.plotter = None
        self.cloud = None
        self.offset = np.zeros(3)  # subtracted from the drawn points (float32 keeps millimetres near the bridge)
        self.actor = None
        self.selected = None
        if not opengl_available():
            msg = QLabel("The 3-D view needs a display with OpenGL (it is not available on this platform).")
            msg.setWordWrap(True)
            self.lay.addWidget(msg, 1)
            self.show_btn.setEnabled(False)

    def _ensure_plotter(self):
        if self.plotter is None:
            from pyvistaqt import QtInteractor

            self.plotter = QtInteractor(self)
            self.plotter.set_background("#1e1e24")
            self.lay.addWidget(self.plotter.interactor, 1)
            self.plotter.enable_point_picking(callback=self._picked, show_message=False, show_point=False,
                                              left_clicking=False, use_picker=True)
        return self.plotter

    def set_cloud(self, cloud) -> None:
        """Draw a :class:`projects.inspection.DisplayCloud`."""
        import pyvista as pv

        self.cloud = cloud
        p = self._ensure_plotter()
        p.clear()
        self.offset = np.median(cloud.xyz, axis=0) if len(cloud.xyz) else np.zeros(3)
        pts = pv.PolyData((cloud.xyz - self.offset).astype(np.float32))
        pts[cloud.value_name] = cloud.values
        bar = dict(title=cloud.value_name, vertical=True, position_x=0.88, position_y=0.1, height=0.8, width=0.06,
                   title_font_size=12, label_font_size=11)
        if cloud.value_name == "intensity":
            lo, hi = np.nanpercentile(cloud.values, [1, 99.5]) if len(cloud.values) else (0, 1)
            actor = p.add_points(pts, scalars=cloud.value_name, cmap="cividis", point_size=2,
                                 clim=(lo, max(hi, lo + 1e-3)), scalar_bar_args=bar)
        else:  # signed change: diverging colours, symmetric about zero
            finite = np.isfinite(cloud.values)
            lim = float(np.nanpercentile(np.abs(cloud.values), 98)) if finite.any() else 1.0
            actor = p.add_points(pts, scalars=cloud.value_name, cmap="RdBu", point_size=5, clim=(-lim, lim),
                                 nan_color="grey", scalar_bar_args=bar)
        self.actor = with_interactive_lod(p, actor, pts)
        self._draw_markers()
        p.view_vector((-0.45, -1.0, 0.35), viewup=(0, 0, 1))  # oblique, from the scanner's side, z up
        p.reset_camera()
        p.render()
        self.info.setText(f"{len(cloud.xyz):,} of {cloud.n_total:,} points shown ({cloud.frame}); "
                          f"right-click near a target to select it")

    def _draw_markers(self) -> None:
        import pyvista as pv

        cloud, p = self.cloud, self.plotter
        if cloud is None or not len(cloud.marker_xyz):
            return
        xyz = cloud.marker_xyz - self.offset
        for name in ("markers", "markers_sel", "labels"):
            p.remove_actor(name)
        sel = [k for k, i in enumerate(cloud.marker_ids) if i == self.selected]
        rest = [k for k in range(len(xyz)) if k not in sel]
        if rest:
            p.add_mesh(pv.PolyData(xyz[rest]).glyph(geom=pv.Sphere(radius=0.12), scale=False, orient=False),
                       color="#ff5555", name="markers")
        if sel:
            p.add_mesh(pv.PolyData(xyz[sel]).glyph(geom=pv.Sphere(radius=0.2), scale=False, orient=False),
                       color="yellow", name="markers_sel")
        p.add_point_labels(xyz, list(cloud.marker_ids), font_size=14, text_color="white", shape_opacity=0.4,
                           name="labels", always_visible=True)

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

"""Camera cross-validation: overlay, differences over time and the 1:1 scatter, with the statistics."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from app.gui.views.mpl import PlotCanvas
from vision.figures import difference_figure, overlay_figure, scatter_figure


class CameraView(QWidget):
    """Signals ``crossvalRequested()`` and ``importRequested()``."""
    crossvalRequested = Signal()
    importRequested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.info = QLabel("No camera series in this campaign: import one (Camera ▸ Import series…).")
        self.info.setWordWrap(True)
        imp = QPushButton("Import series…")
        imp.clicked.connect(self.importRequested)
        self.run_btn = QPushButton("Cross-validate again")
        self.run_btn.clicked.connect(self.crossvalRequested)
        bar = QHBoxLayout()
        bar.addWidget(self.info, 1)
        bar.addWidget(imp)
        bar.addWidget(self.run_btn)
        self.canvas = PlotCanvas(self, figsize=(10, 7))
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.canvas, 1)
        self.result = None

    def set_result(self, cv, camera) -> None:
        """Draw a :class:`vision.crossval.CrossValidation` with its camera series."""
        self.result = cv
        fig = self.canvas.figure
        fig.clear()
        grid = fig.add_gridspec(2, 3)
        overlay_figure(cv, camera, ax=fig.add_subplot(grid[0, :]))
        difference_figure(cv, ax=fig.add_subplot(grid[1, :2]))
        scatter_figure(cv, ax=fig.add_subplot(grid[1, 2]))
        self.canvas.draw_idle()
        al = cv.alignment
        how = f"aligned at {al['epoch']}" if al["method"] == "at-date" else "aligned by least squares"
        self.info.setText(f"<b>{cv.series}</b> against LiDAR {cv.reflector}: {cv.n_pairs} pairs, {how} "
                          f"(offset {cv.offset_mm:+.2f} mm); {cv.statistics_text()}")

    def show_message(self, text: str) -> None:
        self.result = None
        self.info.setText(text)
        self.canvas.figure.clear()
        self.canvas.draw_idle()

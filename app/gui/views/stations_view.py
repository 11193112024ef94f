"""Where to stand: the station map over the layout, coloured by the worst target's predicted sigma, and
the best candidates in a table."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QDoubleSpinBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.gui.views.mpl import PlotCanvas
from projects.onsite.stations import draw_station_map

TOP = 10


class StationsView(QWidget):
    """Emits ``evaluateRequested(grid_m, height_m)`` when the user asks for an evaluation."""
    evaluateRequested = Signal(float, float)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.canvas = PlotCanvas(self, figsize=(8, 5.5))
        self.grid = QDoubleSpinBox()
        self.grid.setRange(0.5, 20.0)
        self.grid.setValue(2.0)
        self.grid.setSuffix(" m grid")
        self.height = QDoubleSpinBox()
        self.height.setRange(0.3, 10.0)
        self.height.setValue(1.5)
        self.height.setSuffix(" m instrument height")
        self.run_btn = QPushButton("Evaluate stations")
        self.run_btn.clicked.connect(self.request_evaluation)
        self.info = QLabel("Predicts, for scanner positions on a grid around the bridge, the sigma of every target's "
                           "displacement and the scan time.")
        self.info.setWordWrap(True)
        self.table = QTableWidget(0, 5)
        self.table.setHorizontalHeaderLabels(["x (m)", "y (m)", "minutes", "worst σ (mm)", "hidden · weak"])
        self.table.setMaximumHeight(200)
        self.table.setMinimumHeight(90)
        self.table.horizontalHeader().setStretchLastSection(True)
        bar = QHBoxLayout()
        for w in (self.grid, self.height, self.run_btn):
            bar.addWidget(w)
        bar.addStretch(1)
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.info)
        lay.addWidget(self.canvas, 1)
        lay.addWidget(self.table)
        self.advice = None

    def request_evaluation(self) -> None:
        """Ask for an evaluation with the grid and height shown."""
        self.evaluateRequested.emit(self.grid.value(), self.height.value())

    def show_message(self, text: str) -> None:
        self.advice = None
        self.info.setText(text)
        self.table.setRowCount(0)
        self.canvas.figure.clear()
        self.canvas.draw_idle()

    def show_advice(self, advice, layout) -> None:
        """Draw a :class:`projects.stations.StationAdvice` over its layout."""
        self.advice = advice
        fig = self.canvas.figure
        fig.clear()
        draw_station_map(fig.add_subplot(111), advice, layout)
        self.canvas.draw_idle()
        best = advice.stations[:TOP]
        self.table.setRowCount(len(best))
        self.table.resizeColumnsToContents()
        for r, s in enumerate(best):
            worst = "–" if s.worst_sigma_mm == float("inf") else f"{s.worst_sigma_mm:.3f}"
            for c, v in enumerate((f"{s.xyz_layout[0]:.1f}", f"{s.xyz_layout[1]:.1f}", f"{s.seconds / 60:.1f}", worst,
                                   _hidden_weak(s))):
                item = QTableWidgetItem(v)
                item.setToolTip(v)
                self.table.setItem(r, c, item)
        self.info.setText(f"{len(advice.stations)} positions evaluated for a {advice.scanner}; ground at "
                          f"z = {advice.ground_z:.2f} m ({advice.ground_source}). Best first.")


def _hidden_weak(s) -> str:
    """The targets a station cannot measure, then those it measures only at grazing incidence."""
    text = ", ".join(s.hidden) or "–"
    return text + (f" · weak: {', '.join(s.weak)}" if s.weak else "")

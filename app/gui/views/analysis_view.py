"""The analysis of a campaign: per target the thermal coefficient, event steps and creep, trend and
projection in a table, and the selected target's temperature-corrected history."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import QHBoxLayout, QLabel, QPushButton, QTableWidget, QTableWidgetItem, QVBoxLayout, QWidget

from app.gui.views.mpl import PlotCanvas

COLUMNS = ["target", "mm/°C", "σ", "trend mm/yr", "events (step mm, creep coefficient)", "projection"]


class AnalysisView(QWidget):
    """Emits ``runRequested`` when the user asks for the analysis."""
    runRequested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.run_btn = QPushButton("Analyse")
        self.run_btn.clicked.connect(self.runRequested.emit)
        self.info = QLabel("Temperature effect, construction events with creep, trend and projection of every "
                           "target (import a temperature series and add events first).")
        self.info.setWordWrap(True)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.setMaximumHeight(200)
        self.table.currentCellChanged.connect(lambda r, *_: self._draw(r))
        self.canvas = PlotCanvas(self, figsize=(8, 4))
        bar = QHBoxLayout()
        bar.addWidget(self.run_btn)
        bar.addWidget(self.info, 1)
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.table)
        lay.addWidget(self.canvas, 1)
        self.doc = None

    def show_analysis(self, doc: dict) -> None:
        self.doc = doc
        targets = doc["targets"]
        self.table.setRowCount(len(targets))

        def num(v, f="{:.3f}"):
            return "–" if v is None else f.format(v)
        for r, t in enumerate(targets):
            ev = "; ".join(f"{e['label']}: {num(e['step_mm'], '{:.2f}')}, φ {num(e['creep_coefficient'], '{:.2f}')}"
                           for e in t["events"]) or "–"
            vals = [t["reflector"], num(t["thermal_mm_per_degC"]), num(t["thermal_sigma"]),
                    num(t["trend_mm_per_year"], "{:.2f}"), ev, (t["projection"] or {}).get("warning", "–")]
            for c, v in enumerate(vals):
                self.table.setItem(r, c, QTableWidgetItem(v))
        self.table.resizeColumnsToContents()
        warn = " ".join(f"⚠ {w}" for w in doc["warnings"])
        self.info.setText(f"Temperature: {doc['temperature_source'] or 'none'}; {len(doc['events'])} event(s). {warn}")
        if targets:
            self.table.selectRow(len(targets) // 2)
            self._draw(len(targets) // 2)

    def _draw(self, row: int) -> None:
        if self.doc is None or not 0 <= row < len(self.doc["targets"]):
            return
        from projects.analysis.figures import draw_target

        fig = self.canvas.figure
        fig.clear()
        draw_target(fig.add_subplot(111), self.doc, self.doc["targets"][row])
        self.canvas.draw_idle()

"""The analysis of a campaign: per target the thermal coefficient, event steps and creep, trend and
projection in a table, and the selected target's temperature-corrected history."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.gui.views.mpl import PlotCanvas
from projects.analysis.figures import draw_target

COLUMNS = ["target", "mm/°C", "σ", "trend mm/yr", "events (step mm, creep coefficient)", "projection"]


def _num(v, f="{:.3f}") -> str:
    return "–" if v is None else f.format(v)


def event_text(e: dict) -> str:
    """An event's step and creep in words; a negative creep coefficient says what it means."""
    phi, sig = e.get("creep_coefficient"), e.get("creep_coefficient_sigma")
    text = f"{e['label']}: step {_num(e['step_mm'], '{:+.1f}')} mm"
    if phi is None:
        return text + ", creep not fitted"
    if phi < 0:
        unclear = sig is not None and abs(phi) < 2 * sig
        return text + f", φ {phi:.2f} " + ("(not determinable: within 2σ of zero)" if unclear else
                                            "(a recovery after the step, not creep)")
    return text + f", φ {phi:.2f}" + (f" ± {sig:.2f}" if sig is not None else "")


class AnalysisView(QWidget):
    """Emits ``runRequested`` when the user asks for the analysis, ``importRequested`` for a temperature series."""
    runRequested = Signal()
    importRequested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.run_btn = QPushButton("Analyse")
        self.run_btn.clicked.connect(self.runRequested.emit)
        self.import_btn = QPushButton("Import temperature…")
        self.import_btn.setToolTip("Analysis ▸ Import environment series…")
        self.import_btn.clicked.connect(self.importRequested.emit)
        self.info = QLabel("Temperature effect, construction events with creep, trend and projection of every "
                           "target (import a temperature series and add events first).")
        self.info.setWordWrap(True)
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.setMaximumHeight(260)
        self.table.setMinimumHeight(90)
        self.table.setWordWrap(True)
        header = self.table.horizontalHeader()
        for col in range(len(COLUMNS)):  # the two texts share what the numbers leave, wrapped
            header.setSectionResizeMode(col, QHeaderView.Stretch if col >= 4 else QHeaderView.ResizeToContents)
        self.table.verticalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.table.currentCellChanged.connect(lambda r, *_: self._draw(r))
        self.canvas = PlotCanvas(self, figsize=(8, 4))
        bar = QHBoxLayout()
        bar.addWidget(self.run_btn)
        bar.addWidget(self.import_btn)
        bar.addWidget(self.info, 1)
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.table)
        lay.addWidget(self.canvas, 1)
        self.doc = None

    def show_message(self, text: str) -> None:
        self.doc = None
        self.info.setText(text)
        self.table.setRowCount(0)
        self.canvas.figure.clear()
        self.canvas.draw_idle()

    def show_analysis(self, doc: dict) -> None:
        self.doc = doc
        targets = doc["targets"]
        self.table.setRowCount(len(targets))

        for r, t in enumerate(targets):
            ev = "\n".join(event_text(e) for e in t["events"]) or "–"
            vals = [t["reflector"], _num(t["thermal_mm_per_degC"]), _num(t["thermal_sigma"]),
                    _num(t["trend_mm_per_year"], "{:.2f}"), ev, (t["projection"] or {}).get("warning", "–")]
            for c, v in enumerate(vals):
                item = QTableWidgetItem(v)
                item.setToolTip(v)
                self.table.setItem(r, c, item)
        self.table.resizeRowsToContents()
        warn = " ".join(f"⚠ {w}" for w in doc["warnings"])
        self.info.setText(f"Temperature: {doc['temperature_source'] or 'none'}; {len(doc['events'])} event(s). {warn}")
        if targets:
            self.table.selectRow(len(targets) // 2)
            self._draw(len(targets) // 2)

    def _draw(self, row: int) -> None:
        if self.doc is None or not 0 <= row < len(self.doc["targets"]):
            return

        fig = self.canvas.figure
        fig.clear()
        draw_target(fig.add_subplot(111), self.doc, self.doc["targets"][row])
        self.canvas.draw_idle()

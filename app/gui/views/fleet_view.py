"""The fleet page: every bridge under a folder, worst state first; open any of them."""
from __future__ import annotations

from PySide6.QtCore import Signal
from PySide6.QtGui import QColor
from PySide6.QtWidgets import QDialog, QHBoxLayout, QLabel, QPushButton, QTableWidget, QTableWidgetItem, QVBoxLayout

STATE_COLOURS = {"ok": "#c8e6c9", "warning": "#ffe0b2", "alarm": "#ffcdd2", "unknown": "#eeeeee",
                 "unreadable": "#e0e0e0"}
COLUMNS = ["bridge", "state", "worst target", "displacement (mm)", "alarm (mm)", "last epoch", "days since",
           "work left", "problems", "folder"]


class FleetView(QDialog):
    """Emits ``openRequested(folder)`` when the user opens a bridge."""
    openRequested = Signal(str)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Fleet")
        self.summary = QLabel("")
        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.setSelectionBehavior(QTableWidget.SelectRows)
        self.table.setEditTriggers(QTableWidget.NoEditTriggers)
        self.table.cellDoubleClicked.connect(lambda r, _c: self._open(r))
        self.open_btn = QPushButton("Open the selected bridge")
        self.open_btn.clicked.connect(lambda: self._open(self.table.currentRow()))
        close = QPushButton("Close")
        close.clicked.connect(self.close)
        row = QHBoxLayout()
        row.addWidget(self.open_btn)
        row.addStretch(1)
        row.addWidget(close)
        lay = QVBoxLayout(self)
        lay.addWidget(self.summary)
        lay.addWidget(self.table, 1)
        lay.addLayout(row)
        self.folders: list[str] = []
        self.resize(1100, 420)

    def show_status(self, status: dict) -> None:
        """Fill from :func:`projects.fleet.fleet_status`."""
        bridges = status["bridges"]
        self.folders = [b["folder"] for b in bridges]
        self.table.setRowCount(len(bridges))
        for r, b in enumerate(bridges):
            state = "unreadable" if b["error"] else b["state"]

            def num(v):
                return "–" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v)
            vals = [b["name"], state, b["worst_target"] or "–", num(b["worst_displacement_mm"]),
                    num(b["worst_limit_mm"]), b["last_epoch"] or "–", num(b["days_since"]), str(b["work_left"]),
                    str(b["problems"]), b["folder"] if not b["error"] else f"{b['folder']}: {b['error']}"]
            for c, v in enumerate(vals):
                item = QTableWidgetItem(v)
                if c == 1:
                    item.setBackground(QColor(STATE_COLOURS.get(state, "#eeeeee")))
                self.table.setItem(r, c, item)
        self.table.resizeColumnsToContents()
        ov = status["overview"]
        self.summary.setText(f"{ov['bridges']} bridges: {ov['alarm']} in alarm, {ov['warning']} warning, "
                             f"{ov['ok']} ok, {ov['unknown']} unknown, {ov['unreadable']} unreadable; "
                             f"{ov['work_left']} epoch(s) with work left"
                             + (f"; overdue: {', '.join(ov['overdue'])}" if ov["overdue"] else ""))
        if bridges:
            self.table.selectRow(0)

    def _open(self, row: int) -> None:
        if 0 <= row < len(self.folders):
            self.openRequested.emit(self.folders[row])

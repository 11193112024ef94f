"""Dialogs: new campaign, add epoch, import a camera series; and the one way errors are shown."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

from PySide6.QtCore import QDateTime, Qt, QTimeZone
from PySide6.QtWidgets import (QComboBox, QDateTimeEdit, QDialog, QDialogButtonBox, QDoubleSpinBox, QFileDialog,
                               QFormLayout, QHBoxLayout, QLabel, QLineEdit, QListWidget, QMessageBox, QPushButton,
                               QVBoxLayout, QWidget)

from common.errors import SurveyError

SCAN_FILTER = "Scans (*.las *.laz *.e57 *.ply *.pcd *.ptx *.xyz *.txt *.asc);;All files (*)"


def show_error(parent, title: str, message: str) -> None:
    """The one way the GUI reports a failure: a dialog with the message (never a traceback)."""
    QMessageBox.critical(parent, title, message)


class _PathField(QWidget):
    """A line edit with a Browse button (a file to open, several files, or a folder)."""

    def __init__(self, mode: str = "file", filter_: str = "All files (*)", parent=None):
        super().__init__(parent)
        self.mode, self.filter = mode, filter_
        self.edit = QLineEdit()
        btn = QPushButton("Browse…")
        btn.clicked.connect(self._browse)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.edit)
        lay.addWidget(btn)

    def _browse(self) -> None:
        if self.mode == "folder":
            p = QFileDialog.getExistingDirectory(self, "Choose a folder")
        else:
            p, _ = QFileDialog.getOpenFileName(self, "Choose a file", "", self.filter)
        if p:
            self.edit.setText(p)

    def text(self) -> str:
        return self.edit.text().strip()


def _buttons(dialog: QDialog, layout) -> None:
    box = QDialogButtonBox(QDialogButtonBox.Ok | QDialogButtonBox.Cancel)
    box.accepted.connect(dialog.accept)
    box.rejected.connect(dialog.reject)
    layout.addWidget(box)


class NewCampaignDialog(QDialog):
    """Folder, name, layout CSV, span and default target diameter of a new campaign."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setWindowTitle("New campaign")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.folder = _PathField("folder")
        self.name = QLineEdit()
        self.layout_csv = _PathField("file", "Layout (*.csv);;All files (*)")
        self.span = QDoubleSpinBox(decimals=2, minimum=0.0, maximum=5000.0, value=0.0, suffix=" m")
        self.span.setSpecialValueText("unknown")
        self.diameter = QDoubleSpinBox(decimals=0, minimum=5, maximum=1000, value=50, suffix=" mm")
        form.addRow("Campaign folder", self.folder)
        form.addRow("Structure name", self.name)
        form.addRow("Reflector layout (id,group,x,y,z)", self.layout_csv)
        form.addRow("Span", self.span)
        form.addRow("Target diameter", self.diameter)
        lay.addLayout(form)
        _buttons(self, lay)

    def values(self) -> dict:
        return {"folder": self.folder.text(), "name": self.name.text().strip(), "layout": self.layout_csv.text(),
                "span_m": self.span.value() or None, "diameter_mm": self.diameter.value()}


class AddEpochDialog(QDialog):
    """Date and time, label, coarse scan, fine scans and station notes of a visit."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Add epoch")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.when = QDateTimeEdit(QDateTime.currentDateTime().toTimeZone(QTimeZone.utc()))
        self.when.setDisplayFormat("yyyy-MM-dd HH:mm 'UTC'")
        self.when.setTimeZone(QTimeZone.utc())
        self.when.setCalendarPopup(True)
        self.label = QLineEdit()
        self.label.setPlaceholderText("default: the date")
        self.coarse = _PathField("file", SCAN_FILTER)
        self.fines = QListWidget()
        self.fines.setMaximumHeight(80)
        add_fine = QPushButton("Add fine scans…")
        add_fine.clicked.connect(self._add_fines)
        self.notes = QLineEdit()
        form.addRow("Date and time", self.when)
        form.addRow("Label", self.label)
        form.addRow("Coarse scan", self.coarse)
        form.addRow("Fine scans (optional)", self.fines)
        form.addRow("", add_fine)
        form.addRow("Station notes", self.notes)
        lay.addLayout(form)
        _buttons(self, lay)

    def _add_fines(self) -> None:
        paths, _ = QFileDialog.getOpenFileNames(self, "Fine scans", "", SCAN_FILTER)
        for p in paths:
            self.fines.addItem(p)

    def values(self) -> dict:
        iso = self.when.dateTime().toUTC().toString(Qt.ISODate)
        return {"datetime": iso, "label": self.label.text().strip() or iso[:10], "coarse": self.coarse.text(),
                "fines": [self.fines.item(i).text() for i in range(self.fines.count())],
                "notes": self.notes.text().strip()}


class ImportCameraDialog(QDialog):
    """A camera series file and how to read it."""

    def __init__(self, reflectors: list[str], default: Optional[str], parent=None):
        super().__init__(parent)
        self.setWindowTitle("Import camera series")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.file = _PathField("file", "Series (*.csv *.txt *.tsv *.dat);;All files (*)")
        self.name = QLineEdit()
        self.name.setPlaceholderText("default: the file name")
        self.reflector = QComboBox()
        self.reflector.addItems(reflectors)
        if default in reflectors:
            self.reflector.setCurrentText(default)
        self.timezone = QLineEdit("UTC")
        self.positive = QComboBox()
        self.positive.addItems(["up", "down"])
        form.addRow("File", self.file)
        form.addRow("Series name", self.name)
        form.addRow("LiDAR target watched", self.reflector)
        form.addRow("Zone of times without offset", self.timezone)
        form.addRow("Positive displacement is", self.positive)
        lay.addLayout(form)
        _buttons(self, lay)

    def values(self) -> dict:
        return {"file": self.file.text(), "name": self.name.text().strip() or None,
                "reflector": self.reflector.currentText() or None, "timezone": self.timezone.text().strip() or "UTC",
                "positive": self.positive.currentText()}


def ask_save_path(parent, title: str, default: str, filter_: str) -> Optional[Path]:
    p, _ = QFileDialog.getSaveFileName(parent, title, default, filter_)
    return Path(p) if p else None


class CheckDialog(QDialog):
    """The on-site check of an epoch: one row per target, and a button to save the re-scan plan."""

    def __init__(self, parent, result):
        from PySide6.QtGui import QColor
        from PySide6.QtWidgets import QPushButton, QTableWidget, QTableWidgetItem

        super().__init__(parent)
        self.result = result
        self.setWindowTitle(f"Check of epoch {result.epoch}")
        cols = ["target", "status", "points", "planned", "σ (mm)", "goal σ (mm)", "note"]
        table = QTableWidget(len(result.targets), len(cols))
        table.setHorizontalHeaderLabels(cols)
        colours = {"ok": "#c8e6c9", "short": "#ffe0b2", "imprecise": "#ffe0b2", "not found": "#ffcdd2"}
        for r, t in enumerate(result.targets):
            vals = (t.reflector, t.status, str(t.points), str(t.planned_points),
                    "–" if t.sigma_mm != t.sigma_mm else f"{t.sigma_mm:.3f}",
                    "–" if t.goal_sigma_mm != t.goal_sigma_mm else f"{t.goal_sigma_mm:.3f}", t.note)
            for c, v in enumerate(vals):
                item = QTableWidgetItem(v)
                if c == 1:
                    item.setBackground(QColor(colours.get(t.status, "#eeeeee")))
                table.setItem(r, c, item)
        table.resizeColumnsToContents()
        short = result.short
        text = ("Every target is good: the visit is complete." if not short else
                f"Re-scan {', '.join(t.reflector for t in short)} before leaving "
                f"({result.rescan.total_seconds / 60:.1f} min).")
        self.summary = QLabel(text)
        self.save_btn = QPushButton("Save re-scan plan…")
        self.save_btn.setEnabled(result.rescan is not None)
        self.save_btn.clicked.connect(self._save)
        close = QPushButton("Close")
        close.clicked.connect(self.accept)
        row = QHBoxLayout()
        row.addWidget(self.save_btn)
        row.addStretch(1)
        row.addWidget(close)
        lay = QVBoxLayout(self)
        lay.addWidget(self.summary)
        lay.addWidget(table)
        lay.addLayout(row)
        self.table = table
        self.resize(820, 360)

    def _save(self) -> None:
        path = ask_save_path(self, "Save re-scan plan", f"rescan-{self.result.epoch}.json", "Plan (*.json)")
        if path is not None:
            try:
                self.result.rescan.save(path)
            except (SurveyError, OSError) as exc:
                show_error(self, "Save re-scan plan", str(exc))

"""Dialogs: new campaign, add epoch, limits, imports (camera, environment series, events, design
predictions), the on-site check; the file choosers (each kind starts in the folder used last) and
the one way errors are shown."""
from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QDate, QDateTime, Qt, QTimeZone
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDateEdit,
    QDateTimeEdit,
    QDialog,
    QDialogButtonBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QListWidget,
    QMessageBox,
    QPushButton,
    QRadioButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from app.gui.state.folders import LastFolders
from common.errors import SurveyError
from lidar.io.scan_time import scan_file_time
from projects.series.environment import EVENT_KINDS, KINDS

SCAN_FILTER = "Scans (*.las *.laz *.e57 *.ply *.pcd *.ptx *.xyz *.txt *.asc);;All files (*)"
SERIES_FILTER = "Series (*.csv *.txt *.tsv *.dat);;All files (*)"


def show_error(parent, title: str, message: str) -> None:
    """The one way the GUI reports a failure: a dialog with the message (never a traceback)."""
    QMessageBox.critical(parent, title, message)


# ---------------------------------------------------------------------- file choosers
def ask_open_file(parent, title: str, folders: LastFolders | None, kind: str, filter_: str) -> str:
    p, _ = QFileDialog.getOpenFileName(parent, title, folders.start(kind) if folders else "", filter_)
    if p and folders:
        folders.remember(kind, p)
    return p


def ask_files(parent, title: str, folders: LastFolders | None, kind: str, filter_: str = SCAN_FILTER) -> list[str]:
    paths, _ = QFileDialog.getOpenFileNames(parent, title, folders.start(kind) if folders else "", filter_)
    if paths and folders:
        folders.remember(kind, paths[0])
    return list(paths)


def ask_folder(parent, title: str, folders: LastFolders | None, kind: str) -> str:
    p = QFileDialog.getExistingDirectory(parent, title, folders.start(kind) if folders else "")
    if p and folders:
        folders.remember(kind, p)
    return p


def ask_save_path(parent, title: str, folders: LastFolders | None, default: str, filter_: str,
                  kind: str = "outputs") -> Path | None:
    p, _ = QFileDialog.getSaveFileName(parent, title, folders.start(kind, default) if folders else default, filter_)
    if p and folders:
        folders.remember(kind, p)
    return Path(p) if p else None


class _PathField(QWidget):
    """A line edit with a Browse button (a file to open or a folder); ``kind`` names the folder memory."""

    def __init__(self, mode: str = "file", filter_: str = "All files (*)", *, kind: str = "scans",
                 folders: LastFolders | None = None, parent=None):
        super().__init__(parent)
        self.mode, self.filter, self.kind, self.folders = mode, filter_, kind, folders
        self.edit = QLineEdit()
        self.edit.setMinimumWidth(220)
        btn = QPushButton("Browse…")
        btn.clicked.connect(self._browse)
        self.browse_btn = btn
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.edit, 1)
        lay.addWidget(btn)

    def _browse(self) -> None:
        if self.mode == "folder":
            p = ask_folder(self, "Choose a folder", self.folders, self.kind)
        else:
            p = ask_open_file(self, "Choose a file", self.folders, self.kind, self.filter)
        if p:
            self.edit.setText(p)

    def text(self) -> str:
        return self.edit.text().strip()


def _buttons(dialog: QDialog, layout) -> QDialogButtonBox:
    box = QDialogButtonBox(QDialogButtonBox.Ok | QDialogButtonBox.Cancel)
    box.accepted.connect(dialog.accept)
    box.rejected.connect(dialog.reject)
    layout.addWidget(box)
    return box


def _hint(text: str) -> QLabel:
    label = QLabel(text)
    label.setWordWrap(True)
    label.setStyleSheet("color: #555;")
    return label


# ---------------------------------------------------------------------- campaign and epochs
def machine_zone() -> str:
    """This machine's time zone as an IANA name (UTC when the system does not say)."""
    name = bytes(QTimeZone.systemTimeZoneId()).decode()
    return "UTC" if name in ("", "Etc/UTC", "UTC", "Universal", "Zulu") else name


class NewCampaignDialog(QDialog):
    """Folder, name, layout CSV, span, default target diameter and time zone of a new campaign."""

    def __init__(self, parent=None, folders: LastFolders | None = None):
        super().__init__(parent)
        self.setWindowTitle("New campaign")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.folder = _PathField("folder", kind="campaigns", folders=folders)
        self.name = QLineEdit()
        self.layout_csv = _PathField("file", "Layout (*.csv);;All files (*)", kind="layouts", folders=folders)
        self.span = QDoubleSpinBox(decimals=2, minimum=0.0, maximum=5000.0, value=0.0, suffix=" m")
        self.span.setSpecialValueText("unknown")
        self.diameter = QDoubleSpinBox(decimals=0, minimum=5, maximum=1000, value=50, suffix=" mm")
        self.timezone = QComboBox()  # the zone of imported times without an offset (init --timezone)
        self.timezone.setEditable(True)
        self.timezone.addItems(sorted({"UTC", *(bytes(z).decode() for z in QTimeZone.availableTimeZoneIds())}))
        self.timezone.setCurrentText(machine_zone())
        self.timezone.setToolTip("Times in imported files that carry no offset are read in this zone (an IANA name "
                                 "such as Europe/Berlin, or +hh:mm); this machine's zone unless you choose another")
        form.addRow("Campaign folder", self.folder)
        form.addRow("Structure name", self.name)
        form.addRow("Reflector layout (id,group,x,y,z)", self.layout_csv)
        form.addRow("Span", self.span)
        form.addRow("Target diameter", self.diameter)
        form.addRow("Time zone", self.timezone)
        lay.addLayout(form)
        _buttons(self, lay)

    def values(self) -> dict:
        return {"folder": self.folder.text(), "name": self.name.text().strip(), "layout": self.layout_csv.text(),
                "span_m": self.span.value() or None, "diameter_mm": self.diameter.value(),
                "timezone": self.timezone.currentText().strip() or "UTC"}


class AddEpochDialog(QDialog):
    """Date and time, label, coarse scan, fine scans and station notes of a visit.

    The date starts as now; once a coarse scan is chosen it becomes the time the file records (its
    points' GPS times, an E57 ``acquisitionStart`` or the LAS header's creation day), unless the user
    set the date by hand.
    """

    def __init__(self, parent=None, folders: LastFolders | None = None):
        super().__init__(parent)
        self.setWindowTitle("Add epoch")
        self.folders = folders
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.when = QDateTimeEdit(QDateTime.currentDateTime().toTimeZone(QTimeZone.utc()))
        self.when.setDisplayFormat("yyyy-MM-dd HH:mm 'UTC'")
        self.when.setTimeZone(QTimeZone.utc())
        self.when.setCalendarPopup(True)
        self._date_by_hand = False
        self._setting_date = False
        self.when.dateTimeChanged.connect(self._date_edited)
        self.when_source = _hint("now (choose the coarse scan: its own time is used when the file has one)")
        self.label = QLineEdit()
        self.label.setPlaceholderText("default: the date")
        self.coarse = _PathField("file", SCAN_FILTER, kind="scans", folders=folders)
        self.coarse.edit.textChanged.connect(self._coarse_chosen)
        self.fines = QListWidget()
        self.fines.setMaximumHeight(80)
        add_fine = QPushButton("Add fine scans…")
        add_fine.clicked.connect(self._add_fines)
        self.notes = QLineEdit()
        form.addRow("Coarse scan", self.coarse)
        form.addRow("Date and time", self.when)
        form.addRow("", self.when_source)
        form.addRow("Label", self.label)
        form.addRow("Fine scans (optional)", self.fines)
        form.addRow("", add_fine)
        form.addRow("Station notes", self.notes)
        lay.addLayout(form)
        _buttons(self, lay)

    def _date_edited(self, _dt) -> None:
        if not self._setting_date:
            self._date_by_hand = True
            self.when_source.setText("set by hand")

    def _coarse_chosen(self, path: str) -> None:
        if self._date_by_hand or not path.strip() or not Path(path.strip()).is_file():
            return
        t = scan_file_time(path.strip())
        if t is None:
            self.when_source.setText("now: the file records no time of its own")
            return
        self._setting_date = True
        try:
            self.when.setDateTime(QDateTime.fromSecsSinceEpoch(int(t.when.timestamp()), QTimeZone.utc()))
        finally:
            self._setting_date = False
        self.when_source.setText(f"from {t.source}" + (" (the time of day is not in the file)" if t.day_only
                                                          else ""))

    def _add_fines(self) -> None:
        for p in ask_files(self, "Fine scans", self.folders, "scans"):
            self.fines.addItem(p)

    def values(self) -> dict:
        iso = self.when.dateTime().toUTC().toString(Qt.ISODate)
        return {"datetime": iso, "label": self.label.text().strip() or iso[:10], "coarse": self.coarse.text(),
                "fines": [self.fines.item(i).text() for i in range(self.fines.count())],
                "notes": self.notes.text().strip()}


class SetLimitDialog(QDialog):
    """A limit rule for every measurement target or one."""

    RULES = ("kr-rail:0-200", "abs:10,15", "span:1000,500", "prediction:5")

    def __init__(self, parent, targets: list[str], selected: str | None = None):
        super().__init__(parent)
        self.setWindowTitle("Set limit")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.target = QComboBox()
        self.target.addItem("every measurement target", "*")
        for t in targets:
            self.target.addItem(t, t)
        if selected in targets:
            self.target.setCurrentIndex(targets.index(selected) + 1)
        self.rule = QComboBox()
        self.rule.setEditable(True)
        self.rule.addItems(self.RULES)
        form.addRow("Target", self.target)
        form.addRow("Limit rule", self.rule)
        lay.addLayout(form)
        lay.addWidget(_hint("kr-rail:0-200 — the Korean railway limits for speeds up to 200 km/h (needs the span); "
                            "abs:W,A — warning and alarm in mm; span:W,A — span/W and span/A; prediction:T — a "
                            "departure of T mm from the design prediction."))
        _buttons(self, lay)

    def values(self) -> dict:
        return {"reflector": self.target.currentData(), "rule": self.rule.currentText().strip()}


# ---------------------------------------------------------------------- imports
class ImportCameraDialog(QDialog):
    """A camera series file and how to read it."""

    def __init__(self, reflectors: list[str], default: str | None, parent=None,
                 folders: LastFolders | None = None, zone: str = "UTC"):
        super().__init__(parent)
        self.setWindowTitle("Import camera series")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.file = _PathField("file", SERIES_FILTER, kind="series", folders=folders)
        self.name = QLineEdit()
        self.name.setPlaceholderText("default: the file name")
        self.reflector = QComboBox()
        self.reflector.addItems(reflectors)
        if default in reflectors:
            self.reflector.setCurrentText(default)
        self.timezone = QLineEdit(zone)
        self.timezone.setToolTip("the campaign's time zone unless you change it here")
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
                "reflector": self.reflector.currentText() or None, "timezone": self.timezone.text().strip() or None,
                "positive": self.positive.currentText()}


class ImportEnvDialog(QDialog):
    """An environment series (temperature, sun, rain, snow, humidity) and how to read it."""

    def __init__(self, parent=None, folders: LastFolders | None = None, zone: str = "UTC"):
        super().__init__(parent)
        self.setWindowTitle("Import environment series")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.file = _PathField("file", SERIES_FILTER, kind="series", folders=folders)
        self.kind = QComboBox()
        for key, q in KINDS.items():
            self.kind.addItem(f"{q.noun} ({q.stored_unit})", key)
        self.name = QLineEdit()
        self.name.setPlaceholderText("default: the file name")
        self.column = QLineEdit()
        self.column.setPlaceholderText("when the header does not tell")
        self.unit = QLineEdit()
        self.unit.setPlaceholderText("when the header does not tell (degC, degF, K, W/m2, mm, cm, %)")
        self.timezone = QLineEdit(zone)
        self.timezone.setToolTip("the campaign's time zone unless you change it here")
        form.addRow("File", self.file)
        form.addRow("Kind", self.kind)
        form.addRow("Series name", self.name)
        form.addRow("Value column", self.column)
        form.addRow("Unit", self.unit)
        form.addRow("Zone of times without offset", self.timezone)
        lay.addLayout(form)
        lay.addWidget(_hint("A CSV or text file with a time column and a value column; the file is kept "
                            "read-only in the campaign. The temperature explains the seasonal swing in the "
                            "Analysis tab."))
        _buttons(self, lay)

    def values(self) -> dict:
        return {"file": self.file.text(), "kind": self.kind.currentData(), "name": self.name.text().strip() or None,
                "column": self.column.text().strip() or None, "unit": self.unit.text().strip() or None,
                "timezone": self.timezone.text().strip() or None}


class AddEventDialog(QDialog):
    """A construction step, load, repair… with its date and, for a load, the load added."""

    def __init__(self, parent=None, default_date: str | None = None):
        super().__init__(parent)
        self.setWindowTitle("Add event")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.date = QDateEdit(QDate.fromString(default_date, "yyyy-MM-dd") if default_date else QDate.currentDate())
        self.date.setDisplayFormat("yyyy-MM-dd")
        self.date.setCalendarPopup(True)
        self.kind = QComboBox()
        self.kind.addItems(list(EVENT_KINDS))
        self.label = QLineEdit()
        self.label.setPlaceholderText("e.g. superstructure dead load")
        self.load = QDoubleSpinBox(decimals=1, minimum=0.0, maximum=10_000.0, value=0.0, suffix=" kN/m")
        self.load.setSpecialValueText("not given")
        form.addRow("Date", self.date)
        form.addRow("Kind", self.kind)
        form.addRow("Label", self.label)
        form.addRow("Load (kN/m)", self.load)
        lay.addLayout(form)
        lay.addWidget(_hint("The analysis fits each event's immediate step and the creep that follows."))
        _buttons(self, lay)

    def values(self) -> dict:
        return {"date": self.date.date().toString("yyyy-MM-dd"), "kind": self.kind.currentText(),
                "label": self.label.text().strip(), "load_kn_m": self.load.value() or None}


class ImportPredictionDialog(QDialog):
    """A design prediction file, how to align it, and the casting date a file by concrete age needs."""

    def __init__(self, parent=None, folders: LastFolders | None = None, casting: str | None = None):
        super().__init__(parent)
        self.setWindowTitle("Import design prediction")
        lay = QVBoxLayout(self)
        form = QFormLayout()
        self.file = _PathField("file", SERIES_FILTER, kind="series", folders=folders)
        self.lsq = QRadioButton("by least squares over every epoch")
        self.lsq.setChecked(True)
        self.at = QRadioButton("at the epoch nearest")
        self.at_date = QDateEdit(QDate.currentDate())
        self.at_date.setDisplayFormat("yyyy-MM-dd")
        self.at_date.setCalendarPopup(True)
        self.at_date.setEnabled(False)
        self.at.toggled.connect(self.at_date.setEnabled)
        at_row = QWidget()
        ar = QHBoxLayout(at_row)
        ar.setContentsMargins(0, 0, 0, 0)
        ar.addWidget(self.at)
        ar.addWidget(self.at_date)
        ar.addStretch(1)
        self.cast = QCheckBox("concrete cast on")
        self.cast_date = QDateEdit(QDate.fromString(casting[:10], "yyyy-MM-dd") if casting else QDate.currentDate())
        self.cast_date.setDisplayFormat("yyyy-MM-dd")
        self.cast_date.setCalendarPopup(True)
        self.cast.setChecked(bool(casting))
        self.cast_date.setEnabled(bool(casting))
        self.cast.toggled.connect(self.cast_date.setEnabled)
        cast_row = QWidget()
        cr = QHBoxLayout(cast_row)
        cr.setContentsMargins(0, 0, 0, 0)
        cr.addWidget(self.cast)
        cr.addWidget(self.cast_date)
        cr.addStretch(1)
        form.addRow("File", self.file)
        form.addRow("Align", self.lsq)
        form.addRow("", at_row)
        form.addRow("Casting date", cast_row)
        lay.addLayout(form)
        lay.addWidget(_hint("CSV with a 'date' (or 'age_days', with the casting date) column and one column per "
                            "target id in mm positive up, or long form with 'reflector' and 'value_mm'. A limit "
                            "'prediction:T' (Campaign ▸ Set limit…) flags departures of more than T mm."))
        _buttons(self, lay)

    def values(self) -> dict:
        return {"file": self.file.text(),
                "align_at": self.at_date.date().toString("yyyy-MM-dd") if self.at.isChecked() else None,
                "casting_date": self.cast_date.date().toString("yyyy-MM-dd") if self.cast.isChecked() else None}


# ---------------------------------------------------------------------- the on-site check
class CheckDialog(QDialog):
    """The on-site check of an epoch: one row per target, and a button to save the re-scan plan."""

    def __init__(self, parent, result, folders: LastFolders | None = None):
        super().__init__(parent)
        self.result = result
        self.folders = folders
        self.setWindowTitle(f"Check of epoch {result.epoch}")
        cols = ["target", "status", "points", "planned", "σ (mm)", "goal σ (mm)", "note"]
        table = QTableWidget(len(result.targets), len(cols))
        table.setHorizontalHeaderLabels(cols)
        colours = {"ok": "#c8e6c9", "short": "#ffe0b2", "imprecise": "#ffe0b2", "moved": "#ffe0b2", "not found": "#ffcdd2"}
        for r, t in enumerate(result.targets):
            vals = (t.reflector, t.status, str(t.points), str(t.planned_points),
                    "–" if t.sigma_mm != t.sigma_mm else f"{t.sigma_mm:.3f}",
                    "–" if t.goal_sigma_mm != t.goal_sigma_mm else f"{t.goal_sigma_mm:.3f}", t.note)
            for c, v in enumerate(vals):
                item = QTableWidgetItem(v)
                item.setToolTip(v)
                if c == 1:
                    item.setBackground(QColor(colours.get(t.status, "#eeeeee")))
                table.setItem(r, c, item)
        table.resizeColumnsToContents()
        short = result.short
        text = ("Every target is good: the visit is complete. Next: Epoch ▸ Process." if not short else
                f"Re-scan {', '.join(t.reflector for t in short)} before leaving "
                f"({result.rescan.total_seconds / 60:.1f} min).")
        self.summary = QLabel(text)
        self.summary.setWordWrap(True)
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
        path = ask_save_path(self, "Save re-scan plan", self.folders, f"rescan-{self.result.epoch}.json",
                             "Plan (*.json)")
        if path is not None:
            try:
                self.result.rescan.save(path)
            except (SurveyError, OSError) as exc:
                show_error(self, "Save re-scan plan", str(exc))

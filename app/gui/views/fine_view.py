"""One target's fine-scan window: the picture drawn in the worker (:mod:`app.gui.views.fine_figure`), scaled to the
view."""
from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QImage, QPixmap
from PySide6.QtWidgets import QLabel, QSizePolicy, QVBoxLayout, QWidget


class FineScanView(QWidget):
    def __init__(self, parent=None):
        super().__init__(parent)
        self.info = QLabel("Select an epoch with fine scans and a target, then open this view.")
        self.info.setWordWrap(True)
        self.image = QLabel()
        self.image.setAlignment(Qt.AlignCenter)
        self.image.setSizePolicy(QSizePolicy.Ignored, QSizePolicy.Ignored)
        self.image.setMinimumSize(200, 120)
        lay = QVBoxLayout(self)
        lay.addWidget(self.info)
        lay.addWidget(self.image, 1)
        self.inspection = None
        self.picture = None
        self._pixmap: QPixmap | None = None

    def show_message(self, text: str) -> None:
        self.inspection = self.picture = self._pixmap = None
        self.info.setText(text)
        self.image.clear()

    def set_inspection(self, picture) -> None:
        """Show a :class:`app.gui.views.fine_figure.FinePicture` (drawn in the worker)."""
        self.picture, self.inspection = picture, picture.inspection
        h, w, _ = picture.rgba.shape
        self._pixmap = QPixmap.fromImage(QImage(picture.rgba.data, w, h, 4 * w, QImage.Format_RGBA8888).copy())
        self._fit()
        self.info.setText(picture.text)

    def _fit(self) -> None:
        if self._pixmap is not None:
            self.image.setPixmap(self._pixmap.scaled(self.image.size(), Qt.KeepAspectRatio, Qt.SmoothTransformation))

    def resizeEvent(self, event):  # noqa: N802
        super().resizeEvent(event)
        self._fit()

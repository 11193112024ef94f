"""The details panel: the HTML of the selection (built in :mod:`app.gui.state.details_html`) in a text browser."""
from __future__ import annotations

from PySide6.QtGui import QTextOption
from PySide6.QtWidgets import QTextBrowser


class DetailsPanel(QTextBrowser):
    def __init__(self, parent=None):
        super().__init__(parent)
        self.setOpenExternalLinks(False)
        self.setMinimumWidth(200)
        # lines break between words only (Qt's default also breaks a word that does not fit, mid-word)
        self.setWordWrapMode(QTextOption.WrapMode.WordWrap)

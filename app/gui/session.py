"""The open campaign as the GUI sees it: its folder, the selection, and change notifications.

The campaign is opened briefly for each read (shared lock) and for each change (exclusive lock,
inside a job), so the command line can work on the same campaign between the GUI's actions.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

from PySide6.QtCore import QObject, Signal

from app.gui.state.campaign_access import CampaignAccess
from projects.store.campaign import Campaign


class CampaignSession(QObject):
    """Signals: ``changed()`` when the campaign's contents changed; ``selectionChanged()``."""
    changed = Signal()
    selectionChanged = Signal()

    def __init__(self, folder: str | Path, parent=None):
        super().__init__(parent)
        self.access = CampaignAccess(folder)
        self.folder = self.access.folder
        self.reflector: Optional[str] = None
        self.epoch: Optional[str] = None
        with self.read() as c:  # fails early (CampaignError) when the folder holds no campaign
            self.name = c.name

    def read(self) -> Campaign:
        """The campaign opened read-only (shared lock), for ``with session.read() as c``."""
        return self.access.read()

    def write(self) -> Campaign:
        """The campaign opened for a change (exclusive lock), for ``with session.write() as c``."""
        return self.access.write()

    def select(self, *, reflector: Optional[str] = ..., epoch: Optional[str] = ...) -> None:
        """Change the selection (arguments left out keep their value)."""
        changed = False
        if reflector is not ... and reflector != self.reflector:
            self.reflector, changed = reflector, True
        if epoch is not ... and epoch != self.epoch:
            self.epoch, changed = epoch, True
        if changed:
            self.selectionChanged.emit()

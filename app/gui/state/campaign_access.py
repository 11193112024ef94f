"""Opening the application's campaign briefly for each read and each change (no Qt here).

:func:`app.gui.actions` functions take anything with these two methods: the application state's
``access`` (:class:`app.gui.state.app_state.AppState`) is one of these.
"""
from __future__ import annotations

from pathlib import Path

from projects.store.campaign import Campaign


class CampaignAccess:
    """A campaign folder opened on demand: shared lock to read, exclusive lock to change."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)

    def read(self) -> Campaign:
        """The campaign opened read-only (shared lock), for ``with access.read() as c``."""
        return Campaign.open(self.folder, writable=False)

    def write(self) -> Campaign:
        """The campaign opened for a change (exclusive lock), for ``with access.write() as c``."""
        return Campaign.open(self.folder, writable=True)

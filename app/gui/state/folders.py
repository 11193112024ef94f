"""The folder each kind of file dialog opened last (no Qt here; the window stores them in its settings).

>>> store = {}
>>> f = LastFolders(store, fallback="/home/me")
>>> f.start("scans")
'/home/me'
>>> f.remember("scans", "/data/visit-12/coarse.laz"); f.start("scans")
'/data/visit-12'
>>> f.start("scans", "plan.json")  # a file name to save: in that folder
'/data/visit-12/plan.json'
"""
from __future__ import annotations

import os
from collections.abc import MutableMapping
from pathlib import Path

#: The kinds of files the dialogs ask for, each remembered on its own.
KINDS = ("campaigns", "layouts", "scans", "series", "outputs", "archives")


class LastFolders:
    """Where each kind of file dialog starts: the folder of the last file chosen for that kind."""

    def __init__(self, store: MutableMapping[str, str], *, fallback: str | None = None):
        self.store = store
        self.fallback = fallback if fallback is not None else os.getcwd()

    def start(self, kind: str, name: str = "") -> str:
        """The folder to open a ``kind`` dialog in (joined with ``name``, a file name to suggest)."""
        folder = self.store.get(f"folders/{kind}") or self.fallback
        return str(Path(folder) / name) if name else str(folder)

    def remember(self, kind: str, path: str | os.PathLike) -> None:
        """``path`` (a file or a folder) was chosen in a ``kind`` dialog."""
        if kind not in KINDS:
            raise ValueError(f"unknown kind of file {kind!r}")
        p = Path(path)
        folder = p if p.is_dir() else p.parent
        self.store[f"folders/{kind}"] = str(folder)

"""Fixtures the command line's and the application's tests share."""
from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture
def disk(tmp_path) -> Path:
    """An empty folder standing for an archive disk."""
    d = tmp_path / "archive-disk"
    d.mkdir()
    return d

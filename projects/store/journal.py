"""The import journal: one line per imported file, kept beside the database, so no import is ever lost.

Every import appends a line to ``imports.jsonl`` in the campaign folder *before* its database
transaction commits: the stored file, its checksum and size, what it was imported as (an epoch's
coarse or fine scan with the epoch's date and notes, a camera or environment series with the options
it was read with, a design prediction), and when; a visit's own scanner is recorded too. A database restored from a backup over a newer
folder therefore still knows, through the journal, what every newer file in the folder is, and
``bridgesurvey repair`` registers it again. Lines are appended under the campaign's writer lock and
flushed to disk; a torn last line (a crash mid-write) is skipped when read.
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
from pathlib import Path

JOURNAL_NAME = "imports.jsonl"


def append(folder: Path, entry: dict) -> int:
    """Append one entry (JSON-safe) to the campaign's journal and flush it to disk; returns the size before.

    A full disk raises ``OSError`` (ENOSPC) and leaves the journal as it was: the caller's import
    then fails before it commits. An import that fails after its line was written takes the line
    back with :func:`truncate` (the writer lock guarantees nobody appended meanwhile).
    """
    line = (json.dumps(entry, sort_keys=True, default=str) + "\n").encode()
    fd = os.open(folder / JOURNAL_NAME, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        before = os.fstat(fd).st_size
        try:
            written = os.write(fd, line)
            if written != len(line):  # a short write on a nearly full disk: never leave half a line behind
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(folder / JOURNAL_NAME))
            os.fsync(fd)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, before)
            raise
    finally:
        os.close(fd)
    return before


def truncate(folder: Path, size: int) -> None:
    """Take back the lines written after the journal had ``size`` bytes (an import that did not commit)."""
    with contextlib.suppress(OSError):
        os.truncate(folder / JOURNAL_NAME, size)


def entries(folder: Path) -> list[dict]:
    """Every readable entry of the journal, oldest first (none when there is no journal)."""
    try:
        text = (folder / JOURNAL_NAME).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    out = []
    for line in text.splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if isinstance(entry, dict) and isinstance(entry.get("stored_path"), str):
            out.append(entry)
    return out


def latest_by_path(folder: Path) -> dict[str, dict]:
    """The newest entry of each stored path (an import run again after a crash appends a second one)."""
    out: dict[str, dict] = {}
    for e in entries(folder):
        if e["stored_path"]:  # entries about an epoch rather than a file have none
            out[e["stored_path"]] = e
    return out


def entry_for(folder: Path, stored_path: str) -> dict | None:
    """The newest entry of one stored file, or None."""
    return latest_by_path(folder).get(stored_path)

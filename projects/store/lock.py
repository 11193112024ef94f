"""The campaign lock: one writer or any number of readers, and who holds it now.

The lock is an ``flock`` on ``.lock`` in the campaign folder: exclusive for a writer, shared for a
reader, released by the kernel when the process ends however it ends. Each holder adds one line to
the file (a writer first empties it): its process id and start time, when it took the lock, and its
command. A process refused the lock asks the kernel who holds it (``/proc/locks``) and names those
processes with their lines, so a line left by a process that has finished is never taken for the
holder. Where the kernel cannot tell (no ``/proc``, a lock taken on another machine), the message
says so.
"""
from __future__ import annotations

import contextlib
import datetime as dt
import fcntl
import json
import os
import socket
import sys
from pathlib import Path
from typing import IO

from projects.store.errors import CampaignError, CampaignLockedError

LOCK_NAME = ".lock"


def _start_ticks(pid: int) -> int | None:
    """When a process started (clock ticks since boot, ``/proc/PID/stat``), or None where unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    try:
        return int(stat.rsplit(")", 1)[1].split()[19])
    except (IndexError, ValueError):
        return None


def _command_of(pid: int) -> str:
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return ""
    return " ".join(part.decode(errors="replace") for part in raw.split(b"\0") if part)


def _holder_line() -> str:
    argv = " ".join(Path(sys.argv[0]).name if k == 0 else a for k, a in enumerate(sys.argv)) if sys.argv else ""
    return json.dumps({"pid": os.getpid(), "start": _start_ticks(os.getpid()), "host": socket.gethostname(),
                       "taken": dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat(),
                       "command": argv[:200]}) + "\n"


def lock_holders(path: Path) -> list[int] | None:
    """Process ids holding an ``flock`` on ``path`` now (from ``/proc/locks``), or None where that cannot be told."""
    try:
        st = path.stat()
        text = Path("/proc/locks").read_text()
    except OSError:
        return None
    exact, by_inode = [], []
    for line in text.splitlines():
        parts = line.split()
        if "->" in parts:  # a process waiting for the lock, not holding it
            continue
        if len(parts) < 6 or parts[1] != "FLOCK":
            continue
        try:
            pid = int(parts[4])
            major, minor, inode = parts[5].split(":")
        except ValueError:
            continue
        if int(inode) != st.st_ino:
            continue
        by_inode.append(pid)
        if (int(major, 16), int(minor, 16)) == (os.major(st.st_dev), os.minor(st.st_dev)):
            exact.append(pid)
    # overlay file systems report the underlying device: fall back to the inode alone
    return sorted(set(exact or by_inode))


def _recorded(path: Path) -> list[dict]:
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return []
    out = []
    for line in text.splitlines():
        with contextlib.suppress(ValueError, TypeError):
            rec = json.loads(line)
            if isinstance(rec, dict) and isinstance(rec.get("pid"), int):
                out.append(rec)
    return out


def describe_holders(path: Path) -> str:
    """Who holds the lock on ``path`` now, for a message: each process, its command and since when."""
    pids = lock_holders(path)
    if pids is None or not pids:
        return ("another process (BridgeSurvey cannot tell which: the lock may be held from another machine, or "
                "this system does not say who holds file locks)")
    lines = _recorded(path)
    described = []
    for pid in pids:
        start = _start_ticks(pid)
        rec = next((r for r in reversed(lines) if r["pid"] == pid and (start is None or r.get("start") in (None, start))),
                   None)
        if rec is not None:
            when = str(rec.get("taken", "?")).replace("T", " ").replace("+00:00", " UTC")
            described.append(f"BridgeSurvey process {pid} ({rec.get('command') or 'command not recorded'}, "
                             f"holding it since {when})")
        else:
            cmd = _command_of(pid)
            described.append(f"process {pid} ({cmd or 'command unknown'}; when it took the lock is not recorded)")
    return " and ".join(described)


class CampaignLock:
    """The lock of one open campaign (see the module notes); :meth:`acquire` it, :meth:`release` it."""

    def __init__(self, path: Path, fh: IO[str] | None, exclusive: bool):
        self.path = path
        self._fh = fh
        self.exclusive = exclusive

    @classmethod
    def acquire(cls, folder: Path, *, exclusive: bool) -> CampaignLock:
        """Take the lock of ``folder``: exclusive for a writer, shared for a reader; refused in one line."""
        path = folder / LOCK_NAME
        fh: IO[str] | None = None
        try:
            fh = open(path, "a+")
        except OSError as exc:
            if exclusive:
                raise CampaignError(f"{path}: cannot be opened to lock the campaign ({exc.strerror}); the folder "
                                    "must be writable to change the campaign") from None
            with contextlib.suppress(OSError):  # a read-only medium: readers still read
                fh = open(path)
        if fh is None:
            return cls(path, None, exclusive)
        try:
            fcntl.flock(fh, (fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH) | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            raise CampaignLockedError(f"{folder}: the campaign is in use by {describe_holders(path)}; wait for it "
                                      "to finish and try again") from None
        lock = cls(path, fh, exclusive)
        lock._record(truncate=exclusive)
        return lock

    def _record(self, *, truncate: bool) -> None:
        """Add this process's line (a writer first empties the file: every earlier holder has finished)."""
        if self._fh is None:
            return
        with contextlib.suppress(OSError, ValueError):  # a full disk or read-only file: the lock holds anyway
            if truncate:
                self._fh.seek(0)
                self._fh.truncate()
            self._fh.write(_holder_line())
            self._fh.flush()

    def upgrade(self) -> None:
        """Hold the lock exclusively for a moment (a reader upgrading the schema); BlockingIOError when in use."""
        if self._fh is not None:
            fcntl.flock(self._fh, fcntl.LOCK_EX | fcntl.LOCK_NB)

    def downgrade(self) -> None:
        """Share the lock again after :meth:`upgrade`."""
        if self._fh is not None:
            fcntl.flock(self._fh, fcntl.LOCK_SH | fcntl.LOCK_NB)

    def release(self) -> None:
        """Let the lock go; a writer empties the file first, so no line of it outlives it."""
        if self._fh is None:
            return
        if self.exclusive:
            with contextlib.suppress(OSError, ValueError):
                self._fh.seek(0)
                self._fh.truncate()
        with contextlib.suppress(OSError):
            fcntl.flock(self._fh, fcntl.LOCK_UN)
        with contextlib.suppress(OSError):
            self._fh.close()
        self._fh = None

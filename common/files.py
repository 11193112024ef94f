"""Writing output files safely: through a temporary file beside the target, renamed on success.

A full disk is one clear line (:class:`DiskFullError`: "no space left on the device holding FILE:
free N MB and run the command again"), never a traceback, and never half a file.
"""
from __future__ import annotations

import contextlib
import csv
import errno
import fcntl
import hashlib
import io
import math
import os
import re
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from common.errors import InputError, SurveyError

MB = 1 << 20
#: What a write whose size is not known beforehand is assumed to need (an output file, a database change).
DEFAULT_NEED_BYTES = 32 * MB


class DiskFullError(SurveyError):
    """The device a file is written to has no space left; nothing was changed."""


def sha256_of(path: str | os.PathLike, chunk: int = 8 << 20) -> str:
    """The SHA-256 of a file (hex), read in chunks of ``chunk`` bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def free_bytes(path: str | os.PathLike) -> int | None:
    """Bytes free for this user on the device holding ``path`` (or its nearest existing parent); None if unknown."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    try:
        st = os.statvfs(p)
    except OSError:
        return None
    return int(st.f_bavail * st.f_frsize)


def disk_full_error(path: str | os.PathLike, need_bytes: int | None = None) -> DiskFullError:
    """The one-line error for a write to ``path`` that found (or would find) the disk full.

    ``need_bytes`` is what the write needs (default :data:`DEFAULT_NEED_BYTES`); the message asks for
    what is missing of it, at least 1 MB.
    """
    free = free_bytes(path) or 0
    need = DEFAULT_NEED_BYTES if need_bytes is None else int(need_bytes)
    missing = max(1, math.ceil((need - free) / MB))
    return DiskFullError(f"no space left on the device holding {path}: free {missing} MB and run the command again")


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or an exception it was raised from) is the system's 'no space left on device'."""
    seen = 0
    cur: BaseException | None = exc
    while cur is not None and seen < 10:
        if isinstance(cur, OSError) and cur.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        cur = cur.__cause__ or cur.__context__
        seen += 1
    return False


def ensure_free(path: str | os.PathLike, need_bytes: int) -> None:
    """Raise :class:`DiskFullError` before a write of ``need_bytes`` to ``path`` that cannot fit."""
    free = free_bytes(path)
    if free is not None and free < need_bytes:
        raise disk_full_error(path, need_bytes)


#: The temporary name :func:`atomic_output` writes under: ``.STEM.part.SUFFIX`` beside the output.
TEMP_OUTPUT = re.compile(r"^\.[^/]+\.part(\.[A-Za-z0-9]{1,8})?$")


def _hold(tmp: Path) -> int | None:
    """Create ``tmp`` and hold a lock on it while it is written (a file whose lock is free is a killed writer's)."""
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    except OSError:
        return None  # the writer meets the same problem and says it
    with contextlib.suppress(OSError):
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    return fd


def stale_temp_files(folder: str | os.PathLike) -> list[Path]:
    """The temporary output files in ``folder`` that no writer holds (left by a killed command), by name."""
    out: list[Path] = []
    try:
        names = sorted(os.listdir(folder))
    except OSError:
        return out
    for name in names:
        p = Path(folder) / name
        if not TEMP_OUTPUT.match(name) or not p.is_file():
            continue
        try:
            fd = os.open(p, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            continue  # a writer at work holds it
        finally:
            os.close(fd)
        out.append(p)
    return out


def remove_stale_temp_files(folder: str | os.PathLike) -> list[Path]:
    """Remove the temporary output files a killed command left in ``folder``; returns what was removed."""
    removed = []
    for p in stale_temp_files(folder):
        with contextlib.suppress(OSError):
            p.unlink()
            removed.append(p)
    return removed


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed to ``path``, on failure removed.

    A crash never leaves half a file under the final name. The temporary name
    keeps the suffix: some writers (laspy, matplotlib) choose the encoding from it. A full disk,
    met by the writer or by the rename, is a :class:`DiskFullError` (the temporary file removed).
    The temporary file is locked while it is written: the temporary files a killed command left in
    the same folder (their lock free) are removed first.
    """
    final = Path(path)
    tmp = final.with_name(f".{final.stem}.part{final.suffix}")
    remove_stale_temp_files(final.parent)
    held = _hold(tmp)
    try:
        yield tmp
        os.replace(tmp, final)
    except Exception as exc:
        if not is_disk_full(exc):
            raise
        written = tmp.stat().st_size if tmp.exists() else 0
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise disk_full_error(final, max(2 * written, 8 * MB)) from None
    finally:
        if tmp.exists():
            with contextlib.suppress(OSError):
                tmp.unlink()
        if held is not None:
            os.close(held)


def write_atomic(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write text (UTF-8) or bytes to ``path`` through :func:`atomic_output`."""
    with atomic_output(path) as tmp:
        if isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            tmp.write_bytes(data)
    return Path(path)


def json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None (JSON has no NaN), lists for tuples."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def output_folder(path: str | os.PathLike) -> Path:
    """A folder to write results into, created if missing; InputError when a file is in the way."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{out}: cannot create the folder ({exc.strerror})") from None
    return out


def csv_text(rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> str:
    """Rows as CSV text with the given columns (missing values and None as empty cells, extra keys ignored).

    >>> print(csv_text([{"a": 1, "b": None, "c": 3}], ["a", "b"]), end="")
    a,b
    1,
    """
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in columns})
    return buf.getvalue()


def check_output(path: str | os.PathLike, *, folder: bool = False, suffixes: Sequence[str] = ()) -> Path:
    """Refuse an output path that cannot be written, in one line, before any computing starts.

    A file output needs an existing folder it may write in, and must not be a folder itself; a folder
    output (``folder=True``) must not be a file, and is either a folder it may write in or can be
    created (its nearest existing parent is a folder it may write in). ``suffixes`` (lower case, with
    the dot) are the file endings the writer understands. Nothing is created.

    Raises
    ------
    common.errors.InputError
        The path, and what is wrong with it.

    >>> check_output("no-such-folder/plan.json")
    Traceback (most recent call last):
    ...
    common.errors.InputError: no-such-folder/plan.json: the folder no-such-folder does not exist; create it first
    """
    out = Path(path)
    if folder:
        if out.exists() and not out.is_dir():
            raise InputError(f"{out}: is a file, not a folder; give a folder for the outputs (it is created if "
                             "missing)")
        parent = out
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise InputError(f"{out}: cannot create a folder inside {parent}, which is a file")
        if not os.access(parent, os.W_OK | os.X_OK) or not _can_create_in(parent):
            raise InputError(f"{out}: no permission to write in {parent}")
        return out
    if out.is_dir() or str(path).endswith(("/", os.sep)):
        ending = f", ending in {' or '.join(suffixes)}" if suffixes else ""
        raise InputError(f"{out}: is a folder; give the name of the file to write{ending}")
    if suffixes and out.suffix.lower() not in suffixes:
        raise InputError(f"{out}: cannot write '{out.suffix or '(no suffix)'}' here; give a name ending in "
                         + " or ".join(suffixes))
    parent = out.parent
    if not parent.exists():
        raise InputError(f"{out}: the folder {parent} does not exist; create it first")
    if not parent.is_dir():
        raise InputError(f"{out}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK) or (out.exists() and not os.access(out, os.W_OK)) \
            or not _can_create_in(parent):
        raise InputError(f"{out}: no permission to write {'it' if out.exists() else 'in ' + str(parent)}")
    return out


def _can_create_in(folder: Path) -> bool:
    """Whether a file can really be created in ``folder`` (tried, and removed at once).

    ``os.access`` answers yes to root everywhere, also on a read-only file system or in /proc, where the
    writer would fail only after the computing.
    """
    try:
        fd, probe = tempfile.mkstemp(prefix=".bridgesurvey-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True

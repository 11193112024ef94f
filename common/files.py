"""Writing output files safely: through a temporary file beside the target, renamed on success."""
from __future__ import annotations

import contextlib
import csv
import io
import os
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed to ``path``, on failure removed.

    A crash never leaves half a file under the final name. The temporary name
    keeps the suffix: some writers (laspy, matplotlib) choose the encoding from it.
    """
    final = Path(path)
    tmp = final.with_name(f".{final.stem}.part{final.suffix}")
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()


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
    import math

    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def output_folder(path: str | os.PathLike) -> Path:
    """A folder to write results into, created if missing; InputError when a file is in the way."""
    from common.errors import InputError

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
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
    from common.errors import InputError

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
        if not os.access(parent, os.W_OK | os.X_OK):
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
    if not os.access(parent, os.W_OK | os.X_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise InputError(f"{out}: no permission to write {'it' if out.exists() else 'in ' + str(parent)}")
    return out

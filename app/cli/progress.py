"""Progress of long commands as a BridgeSurvey progress callback: a bar on a terminal, lines elsewhere."""
from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Iterator

from tqdm import tqdm

#: Seconds between two progress lines when stderr is not a terminal (a log file, CI, a pipe).
LINE_INTERVAL_S = 2.0


@contextlib.contextmanager
def progress_bar(description: str, *, enabled: bool = True,
                 interval_s: float = LINE_INTERVAL_S) -> Iterator[Callable[..., None]]:
    """Yield a ``progress(fraction, message)`` callback for a long command.

    On a terminal it draws a bar on stderr. Elsewhere (``./run demo > log``, CI) it prints a line
    ``description: 37% message`` when the message changes, at most one every ``interval_s`` seconds
    and none in the first ``interval_s`` (a quick command, or one refused at once, prints no progress),
    and a last line at the end when it printed any, so a long run never looks hung.
    """
    if not enabled:
        yield lambda fraction, message="": None
        return
    if not sys.stderr.isatty():
        yield from _lines(description, interval_s)
        return

    bar = tqdm(total=1000, desc=description, file=sys.stderr, leave=False,
               bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix}")

    def callback(fraction: float, message: str = "") -> None:
        target = int(round(fraction * 1000))
        if target > bar.n:
            bar.update(target - bar.n)
        if message:
            bar.set_postfix_str(message, refresh=False)

    try:
        yield callback
    finally:
        bar.close()


def _lines(description: str, interval_s: float) -> Iterator[Callable[..., None]]:
    state = {"last": time.monotonic(), "message": None, "fraction": 0.0, "printed": None}

    def emit(fraction: float, message: str) -> None:
        line = f"{description}: {100 * fraction:3.0f}%" + (f" {message}" if message else "")
        if line != state["printed"]:
            print(line, file=sys.stderr, flush=True)
            state["printed"] = line
        state["last"] = time.monotonic()

    def callback(fraction: float, message: str = "") -> None:
        state["fraction"] = max(state["fraction"], float(fraction))
        if message and message != state["message"]:
            state["message"] = message
            if time.monotonic() - state["last"] >= interval_s:
                emit(state["fraction"], message)

    try:
        yield callback
    finally:
        if state["printed"] is not None and state["message"] is not None:
            emit(state["fraction"], state["message"])

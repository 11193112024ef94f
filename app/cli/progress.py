"""A terminal progress bar as a BridgeSurvey progress callback."""
from __future__ import annotations

import contextlib
import sys


@contextlib.contextmanager
def progress_bar(description: str, *, enabled: bool = True):
    """Yield a ``progress(fraction, message)`` callback drawing a bar on stderr (only on a terminal)."""
    from tqdm import tqdm

    bar = tqdm(total=1000, desc=description, file=sys.stderr, disable=None if enabled else True, leave=False,
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

"""Progress reporting for long work.

A progress callback is any callable ``progress(fraction, message)`` with
``fraction`` in [0, 1]. It may raise :class:`common.errors.CancelledError` to
stop the work; functions taking one let that exception through untouched.
"""
from __future__ import annotations

from collections.abc import Callable

ProgressCallback = Callable[[float, str], None]


def report(progress: ProgressCallback | None, fraction: float, message: str = "") -> None:
    """Call ``progress`` if one was given, clamping ``fraction`` to [0, 1]."""
    if progress is not None:
        progress(min(1.0, max(0.0, float(fraction))), message)


def scaled(progress: ProgressCallback | None, start: float, stop: float) -> ProgressCallback | None:
    """A callback mapping [0, 1] of a sub-task onto [start, stop] of the whole."""
    if progress is None:
        return None

    def sub(fraction: float, message: str = "") -> None:
        report(progress, start + (stop - start) * fraction, message)

    return sub

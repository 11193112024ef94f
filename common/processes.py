"""Starting worker processes quietly: the multiprocessing resource tracker's noise stays off the terminal.

Python starts one *resource tracker* process per program that uses multiprocessing locks or shared
memory (a Dask LocalCluster, a process pool). When that tracker dies (killed with the rest of a
process group, by the out-of-memory killer), the next lock relaunches it, and the new tracker prints
a ``KeyError`` traceback for every lock released that its predecessor had registered: dozens of
stdlib tracebacks that say nothing to a surveyor. :func:`quiet_resource_tracker` makes the tracker
start with its standard error on the null device (it only ever writes such tracebacks and
"leaked semaphore" notes there) and silences the relaunch warning. Call it where processes are
started; it is idempotent.
"""
from __future__ import annotations

import contextlib
import os
import sys
import warnings
from collections.abc import Iterator
from multiprocessing import resource_tracker


@contextlib.contextmanager
def _stderr_to_null() -> Iterator[None]:
    """Point file descriptor 2 at the null device for a moment (the tracker inherits it)."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def quiet_resource_tracker() -> None:
    """Start (and relaunch) this process's multiprocessing resource tracker with a silent standard error."""
    tracker = resource_tracker._resource_tracker
    if getattr(tracker, "_bridgesurvey_quiet", False):
        return
    launch = tracker.ensure_running

    def ensure_running() -> None:
        fd = getattr(tracker, "_fd", None)
        if fd is not None and tracker._check_alive():  # type: ignore[attr-defined]
            return
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="resource_tracker: process died unexpectedly")
            with _stderr_to_null():
                launch()

    tracker.ensure_running = ensure_running  # type: ignore[method-assign]
    tracker._bridgesurvey_quiet = True  # type: ignore[attr-defined]

"""Starting worker processes quietly: the multiprocessing resource tracker's noise stays off the terminal.

Python starts one *resource tracker* process per program that uses multiprocessing locks or shared
memory (a Dask LocalCluster, a process pool). When that tracker dies (killed with the rest of a
process group, by the out-of-memory killer), the next lock relaunches it, and the new tracker prints
a ``KeyError`` traceback for every lock released that its predecessor had registered: dozens of
stdlib tracebacks that say nothing to a surveyor. :func:`quiet_resource_tracker` makes the tracker
start with its standard error on the null device (it only ever writes such tracebacks and
"leaked semaphore" notes there) and silences the relaunch warning. Call it where processes are
started; it is idempotent.

:func:`run_in_process` runs one long job in a process of its own, with progress and cancel: for work whose
compiled parts hold Python's lock for long stretches (matplotlib's Agg drawing, reportlab), which in a thread
would freeze the desktop application's window however often the job reports progress.
"""
from __future__ import annotations

import contextlib
import os
import pickle
import queue
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator
from multiprocessing import get_context, resource_tracker
from typing import Any

from common.errors import CancelledError, SurveyError


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


#: How often (s) :func:`run_in_process` passes the child's progress on and asks whether to cancel.
POLL_S = 0.1
#: How long (s) a cancelled child may take to stop at its next progress call before it is terminated.
CANCEL_GRACE_S = 5.0


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling, else a :class:`SurveyError` (or RuntimeError) with its message."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        if isinstance(exc, SurveyError):
            return SurveyError(str(exc))
        return RuntimeError("".join(traceback.format_exception(exc)).rstrip())


def _child(fn: Callable, args: tuple, kwargs: dict, out: Any, cancel: Any) -> None:
    """The child process's side of :func:`run_in_process`."""
    def progress(fraction: float, message: str = "") -> None:
        if cancel.is_set():
            raise CancelledError("cancelled")
        out.put(("progress", float(fraction), str(message)))

    try:
        result = fn(*args, progress=progress, **kwargs)
    except BaseException as exc:  # noqa: B036 - every outcome goes back to the parent, which raises it
        out.put(("error", _portable(exc)))
    else:
        out.put(("done", result))


def run_in_process(fn: Callable, /, *args: Any, progress: Callable[[float, str], None] | None = None,
                   **kwargs: Any) -> Any:
    """``fn(*args, progress=..., **kwargs)`` in a new (spawned) process; its result or its exception.

    Parameters
    ----------
    fn : callable
        A module-level function (it is pickled) taking a keyword ``progress(fraction, message)``.
    *args, **kwargs
        Its arguments (pickled).
    progress : callable, optional
        Called in this process with the child's progress, every :data:`POLL_S` seconds at least; when it raises
        (a cancel), the child is told to stop at its next progress call, and is terminated after
        :data:`CANCEL_GRACE_S` seconds if it has not. The exception is then raised here.

    Returns
    -------
    object
        What ``fn`` returned (pickled back). An exception ``fn`` raised is raised here with its message
        (one that cannot be pickled comes back as a :class:`SurveyError` or ``RuntimeError`` with its text).
    """
    quiet_resource_tracker()
    ctx = get_context("spawn")  # not fork: the desktop application has threads (and Qt) running
    out, cancel = ctx.Queue(), ctx.Event()
    # not a daemon: the job may start processes of its own (the report's map pool)
    proc = ctx.Process(target=_child, args=(fn, args, kwargs, out, cancel), daemon=False)
    proc.start()
    last = (0.0, "starting")  # said until the child's first word (a spawned process starts in about a second)
    try:
        while True:
            try:
                msg = out.get(timeout=POLL_S)
            except queue.Empty:
                if not proc.is_alive():  # killed (out of memory, a signal) without a word
                    try:
                        msg = out.get(timeout=POLL_S)  # what it put just before it ended
                    except queue.Empty:
                        raise SurveyError(f"the worker process stopped (exit code {proc.exitcode})") from None
                else:
                    if progress is not None:
                        progress(*last)  # no news: the last word again, and a chance to cancel
                    continue
            kind = msg[0]
            if kind == "progress":
                last = (msg[1], msg[2])
                if progress is not None:
                    progress(*last)
            elif kind == "error":
                raise msg[1]
            else:
                return msg[1]
    except BaseException:
        if proc.is_alive():
            cancel.set()
            proc.join(CANCEL_GRACE_S)
        raise
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join(1.0)
        out.close()

"""Importing heavy packages in the background while the caller works."""
from __future__ import annotations

import importlib
import sys
import threading
from collections.abc import Sequence

#: How often (seconds) the interpreter is handed between threads while a background import runs. An import
#: runs Python for seconds; at the default 5 ms each of the caller's numpy calls would wait that long.
SWITCH_INTERVAL_S = 2e-4


def import_in_background(names: Sequence[str]) -> threading.Thread:
    """Start importing the modules ``names``, in this order, in a daemon thread; the started thread.

    The caller imports them as usual where it needs them: Python's import lock makes it wait for this
    thread's import of the same module, so each is imported once per process. A module that fails to
    import is left to the caller's own import, which raises in its own words. Import what the calling
    thread needs meanwhile before starting: some packages (Open3D) walk ``sys.modules`` while they set up.

    Parameters
    ----------
    names : sequence of str
        Dotted module names.

    Returns
    -------
    threading.Thread
    """
    names = tuple(names)

    def load() -> None:
        try:
            for name in names:
                try:
                    importlib.import_module(name)
                except Exception:  # the caller's own import reports it
                    pass
        finally:
            _quicker_switching(False)

    _quicker_switching(True)
    thread = threading.Thread(target=load, name="import " + ", ".join(names), daemon=True)
    thread.start()
    return thread


_switching = {"running": 0, "interval": 0.0}
_switching_lock = threading.Lock()


def _quicker_switching(start: bool) -> None:
    """Lower the switch interval while any background import runs; restore it when the last one ends."""
    with _switching_lock:
        if start:
            if _switching["running"] == 0:
                _switching["interval"] = sys.getswitchinterval()
                sys.setswitchinterval(min(_switching["interval"], SWITCH_INTERVAL_S))
            _switching["running"] += 1
        else:
            _switching["running"] -= 1
            if _switching["running"] == 0:
                sys.setswitchinterval(_switching["interval"])

"""Long work off the GUI thread: one job at a time, with progress, cancel and clean error messages."""
from __future__ import annotations

import importlib
import logging
import threading
import time
import traceback
from collections.abc import Callable

from PySide6.QtCore import QObject, QThread, Signal

from common.errors import CancelledError, SurveyError
from lidar.native import coarse_map_library

log = logging.getLogger(__name__)

#: Native extensions jobs load. Loading one for the first time in a worker thread while the GUI thread
#: draws with OpenGL can deadlock (the dynamic loader's lock against the GIL: seen with Open3D under
#: VTK), so they are all imported in the GUI thread before the first job starts.
#: The 3-D view's VTK and the worker's matplotlib are loaded then too: imported at the first *3-D ▸ Show* or the first
#: picture, they held the interface for seconds.
NATIVE_MODULES = ("open3d", "_py4dgeo", "laspy", "lazrs", "pye57", "cv2", "scipy.spatial", "scipy.optimize", "pandas",
                  "openpyxl", "reportlab.pdfgen.canvas", "matplotlib.backends.backend_agg", "pyvista", "pyvistaqt",
                  "vtkmodules.vtkRenderingLOD")
_preloaded = False


def preload_native_modules() -> None:
    """Import :data:`NATIVE_MODULES` in the calling (GUI) thread, once; a missing one is left to its job."""
    global _preloaded
    if _preloaded:
        return
    _preloaded = True

    for name in NATIVE_MODULES:
        try:
            importlib.import_module(name)
        except Exception as exc:  # the job that needs it reports the problem in its own words
            log.warning("could not load %s: %s", name, exc)

    try:
        coarse_map_library()  # our own compiled coarse map, loaded by ctypes
    except SurveyError as exc:  # not built: the job that maps a scan reports it in its own words
        log.warning("%s", exc)


class _JobThread(QThread):
    progressed = Signal(float, str)
    succeeded = Signal(object)
    failed = Signal(str, str)  # message, kind: "error" | "cancelled" | "bug"

    def __init__(self, fn: Callable, parent=None):
        super().__init__(parent)
        self._fn = fn
        self._cancel = threading.Event()

    def cancel(self) -> None:
        self._cancel.set()

    def run(self) -> None:  # the worker thread
        def progress(fraction: float, message: str = "") -> None:
            if self._cancel.is_set():
                raise CancelledError()
            self.progressed.emit(float(fraction), str(message))

        try:
            result = self._fn(progress)
        except CancelledError as exc:
            self.failed.emit(str(exc), "cancelled")
        except SurveyError as exc:
            self.failed.emit(str(exc), "error")
        except Exception as exc:  # a bug: say so plainly, keep the traceback in the log
            log.error("unexpected error in a background job:\n%s", traceback.format_exc())
            self.failed.emit(f"unexpected internal error ({type(exc).__name__}: {exc}); this is a bug, "
                             "please report it with the log", "bug")
        else:
            self.succeeded.emit(result)


class JobRunner(QObject):
    """Runs ``fn(progress)`` in a worker thread; the GUI shows progress and can cancel.

    Signals: ``started(title)``, ``progress(fraction, message)``, ``finished(title, ok)`` and
    ``error(title, message, kind)`` (kind: error, cancelled or bug).
    """
    started = Signal(str)
    progress = Signal(float, str)
    finished = Signal(str, bool)
    error = Signal(str, str, str)

    def __init__(self, parent=None):
        super().__init__(parent)
        self._thread: _JobThread | None = None
        self._title = ""

    @property
    def busy(self) -> bool:
        return self._thread is not None

    def run(self, title: str, fn: Callable, on_done: Callable | None = None) -> bool:
        """Start a job; False (and nothing started) while another job runs."""
        if self._thread is not None:
            return False
        preload_native_modules()
        self._title = title
        t = _JobThread(fn, self)
        self._thread = t
        t.progressed.connect(self.progress)

        def ok(result):
            self._thread = None
            if on_done is not None:
                try:
                    on_done(result)
                except SurveyError as exc:
                    self.error.emit(title, str(exc), "error")
                except Exception as exc:  # a bug in the GUI's own follow-up: report it, keep running
                    log.error("unexpected error after %s:\n%s", title, traceback.format_exc())
                    self.error.emit(title, f"unexpected internal error ({type(exc).__name__}: {exc}); this is a "
                                           "bug, please report it with the log", "bug")
            self.finished.emit(title, True)

        def fail(message, kind):
            self._thread = None
            self.error.emit(title, message, kind)
            self.finished.emit(title, False)

        t.succeeded.connect(ok)
        t.failed.connect(fail)
        t.finished.connect(t.deleteLater)
        self.started.emit(title)
        t.start()
        return True

    def cancel(self) -> None:
        if self._thread is not None:
            self._thread.cancel()

    def wait(self, ms: int = 600_000) -> bool:
        """Block until the running job's thread ends (tests and shutdown); True when it did.

        Polls with ``time.sleep``, which releases Python's GIL, so the job can run to its end
        (``QThread.wait`` would hold the GIL and starve it).
        """
        t = self._thread
        deadline = time.monotonic() + ms / 1000.0
        while t is not None and t.isRunning() and time.monotonic() < deadline:
            time.sleep(0.02)
        return t is None or not t.isRunning()

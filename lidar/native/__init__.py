"""Compiled inner loops (C, called through :mod:`ctypes`), with the numpy code as the fallback.

The library ``_coarse_map`` is built from ``coarse_map.c`` when the package is installed (an optional
extension of ``setup.py``: without a C compiler the install goes on and numpy does the work). Its results are
the numpy code's to the bit (tested), so a machine without it gives the same maps, only slower. A library
built from another version of ``coarse_map.c`` than the one beside it is left unused (``./run`` builds it
again when the source changes).

Set ``BRIDGESURVEY_NATIVE=0`` to leave the library unused.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib.machinery
import os
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

_HERE = Path(__file__).resolve().parent


def _ptr(kind):
    return np.ctypeslib.ndpointer(dtype=kind, flags="C_CONTIGUOUS")


@lru_cache(maxsize=1)
def coarse_map_library() -> ctypes.CDLL | None:
    """The compiled coarse-map loops, or None (not built, not loadable, stale, big-endian host or switched off)."""
    if os.environ.get("BRIDGESURVEY_NATIVE", "1") == "0" or sys.byteorder != "little":
        return None
    return load_coarse_map(_HERE)


def load_coarse_map(folder: Path) -> ctypes.CDLL | None:
    """The library ``_coarse_map`` in ``folder`` with its functions declared, or None.

    None when it is missing, cannot be loaded, or was built from another ``coarse_map.c`` than the one in
    ``folder`` (when that file is there).
    """
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = folder / f"_coarse_map{suffix}"
        if path.is_file():
            break
    else:
        return None
    try:
        lib = ctypes.CDLL(str(path))
        lib.bs_source_digest.restype = ctypes.c_char_p
        built_from = lib.bs_source_digest().decode()
    except (OSError, AttributeError):
        return None
    source = folder / "coarse_map.c"
    if source.is_file() and hashlib.sha256(source.read_bytes()).hexdigest()[:16] != built_from:
        return None  # stale: its functions may not be the ones declared below
    i64, f32, i32 = ctypes.c_int64, ctypes.c_float, ctypes.c_int32
    u8, d, f, q = _ptr(np.uint8), _ptr(np.float64), _ptr(np.float32), _ptr(np.int64)
    lib.bs_record_survey.argtypes = [u8, i64, i64, i64, d, d, f, q, u8, f]
    lib.bs_record_survey.restype = None
    lib.bs_record_cells.argtypes = [u8, i64, i64, d, d, f, f32, f32, i32, i32, i32, q, f, f, q, f]
    lib.bs_record_cells.restype = None
    lib.bs_cell_sums.argtypes = [q, f, f, i64, i64, q, d, d, f]
    lib.bs_cell_sums.restype = None
    lib.bs_merge.argtypes = [i64, q, d, d, f, _ptr(np.int32), f, f, f]
    lib.bs_merge.restype = None
    lib.bs_finish.argtypes = [i64, i64, i64, i32, f32, f32, _ptr(np.int32), f, f, f, u8, u8]
    lib.bs_finish.restype = None
    return lib

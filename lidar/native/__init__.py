"""The coarse map's compiled inner loops (C, called through :mod:`ctypes`): the one implementation of its pass.

The library ``_coarse_map`` is built from ``coarse_map.c`` when the package is installed (``setup.py``'s
extension; ``./run setup`` builds it again when the source changes). Every coarse map goes through it: the
campaign's (``add-epoch``, ``plan``, ``process`` bin a scan held in memory, and the library merges and finishes
the cells) and ``plan-file``'s and ``detect``'s (an uncompressed LAS file binned from its records). A library
built from another version of ``coarse_map.c`` than the one beside it is refused.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib.machinery
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

from common.errors import SurveyError

_HERE = Path(__file__).resolve().parent


def _ptr(kind):
    return np.ctypeslib.ndpointer(dtype=kind, flags="C_CONTIGUOUS")


@lru_cache(maxsize=1)
def coarse_map_library() -> ctypes.CDLL:
    """The compiled coarse-map loops.

    Raises
    ------
    SurveyError
        The library is not built, cannot be loaded or is stale, or the machine is big-endian (the loops read
        little-endian LAS records and arrays).
    """
    lib = load_coarse_map(_HERE) if sys.byteorder == "little" else None
    if lib is None:
        raise SurveyError("the compiled coarse map (lidar/native/_coarse_map) is not built here, or was built from "
                          "another lidar/native/coarse_map.c: run './run setup' (it needs a C compiler) to build it")
    return lib


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

"""Array helpers numpy's own functions do too slowly for the sizes a scan has."""
from __future__ import annotations

import numpy as np
from numpy.typing import DTypeLike


def unique_sorted(values: np.ndarray) -> np.ndarray:
    """The distinct values of a 1-D array, sorted: ``np.unique(values)`` by one sort.

    Parameters
    ----------
    values : (N,) array

    Returns
    -------
    (K,) array of the same dtype

    Notes
    -----
    numpy 2.3 and later find the distinct values of an integer array with a hash table, which takes
    1.3 s for a million integers where sorting takes 0.025 s (numpy 2.4 on this project's machines).
    """
    s = np.sort(np.asarray(values).ravel())
    if s.size < 2:
        return s
    keep = np.empty(s.size, bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return s[keep]


def median(values: np.ndarray, *, overwrite_input: bool = False) -> float:
    """``np.median`` of a 1-D array of finite values, without its check for NaN.

    Parameters
    ----------
    values : (N,) array, N > 0, no NaN
    overwrite_input : bool, keyword-only
        Partially sort ``values`` in place instead of a copy (as ``np.median``'s option). Default False.

    Returns
    -------
    float
        The middle value, or the mean of the two middle values (as ``np.median`` computes it).

    Notes
    -----
    ``np.median`` imports ``numpy.ma`` the first time it runs, for its NaN check: 20 ms at the start of a
    command that needs one median.
    """
    v = np.asarray(values).ravel()
    k = v.size // 2
    kth = [k] if v.size % 2 else [k - 1, k]
    if overwrite_input and v.flags.writeable and np.shares_memory(v, values):
        v.partition(kth)
    else:
        v = np.partition(v, kth)
    return float(v[k]) if v.size % 2 else float(np.mean(v[k - 1:k + 1]))


def zeros_prefaulted(sizes_and_dtypes: list[tuple[int, DTypeLike]]) -> list[np.ndarray]:
    """Zeroed 1-D arrays of the given sizes and dtypes, in one block of memory the kernel maps in at once.

    Parameters
    ----------
    sizes_and_dtypes : list of (int, dtype)
        Length and dtype of each array.

    Returns
    -------
    list of (N_k,) arrays, zeroed, each aligned to 64 bytes

    Notes
    -----
    A fresh array is paid for at its first write, one page fault per 4 KiB page: on a virtual machine 0.07 s
    for the 110 MB of a 6.8 M-cell coarse map, a fifth of the map's time. Mapped with ``MAP_POPULATE`` the
    kernel zeroes and maps the whole block in one call (0.04 s). Elsewhere than on Linux this is an ordinary
    zeroed block.
    """
    import mmap

    offsets, total = [], 0
    for n, dtype in sizes_and_dtypes:
        total = -(-total // 64) * 64
        offsets.append(total)
        total += int(n) * np.dtype(dtype).itemsize
    flags = getattr(mmap, "MAP_PRIVATE", 0) | getattr(mmap, "MAP_ANONYMOUS", 0) | getattr(mmap, "MAP_POPULATE", 0)
    block: mmap.mmap | np.ndarray
    try:
        block = mmap.mmap(-1, max(total, 1), flags=flags) if flags else mmap.mmap(-1, max(total, 1))
    except OSError:  # no mapping allowed (a limit on mappings): ordinary memory
        block = np.zeros(max(total, 1), np.uint8)
    return [np.frombuffer(block, dtype=dtype, count=int(n), offset=off)
            for (n, dtype), off in zip(sizes_and_dtypes, offsets)]

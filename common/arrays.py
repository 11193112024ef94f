"""Array helpers numpy's own functions do too slowly for the sizes a scan has."""
from __future__ import annotations

import numpy as np


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

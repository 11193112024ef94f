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


#: The median absolute deviation times this is the standard deviation of normally distributed values
#: (1 / the normal distribution's third quartile, 1.482602..., to the 5 digits every threshold was set with).
MAD_TO_SIGMA = 1.4826


def median_and_sigma(values: np.ndarray, *, skip_nan: bool = False,
                     overwrite_input: bool = False) -> tuple[float, float]:
    """The median of ``values`` and their robust standard deviation, ``MAD_TO_SIGMA`` x the median absolute deviation.

    The background test of every detector: a value stands out when it exceeds the median by a few sigma.

    Parameters
    ----------
    values : array
        Any shape; flattened.
    skip_nan : bool, keyword-only
        Leave NaN values out (``np.nanmedian``). Default False: a NaN makes both NaN, as ``np.median``.
    overwrite_input : bool, keyword-only
        Use ``values`` as work space (its values are lost; no copy is made). Default False.

    Returns
    -------
    median, sigma : float
        In the unit of ``values``.
    """
    v = np.asarray(values)
    if skip_nan:
        med = float(np.nanmedian(v))
        return med, MAD_TO_SIGMA * float(np.nanmedian(np.abs(v - med)))
    med = float(np.median(v, overwrite_input=overwrite_input))
    dev = np.subtract(v, med, out=v if overwrite_input else None)
    np.abs(dev, out=dev)
    return med, MAD_TO_SIGMA * float(np.median(dev, overwrite_input=True))


def thin_to_voxels(xyz: np.ndarray, voxel_m: float) -> np.ndarray:
    """One point of each occupied cube of ``voxel_m``: the first one, the points kept in their order.

    Parameters
    ----------
    xyz : (N, 3) float array, metres
    voxel_m : float
        Edge of the cubes (aligned on multiples of it), metres.

    Returns
    -------
    (M, 3) array of ``xyz``'s rows (M <= N)
    """
    key = np.floor(xyz / voxel_m).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)
    return xyz[np.sort(first)]

"""The header of the binary PCD files BridgeSurvey writes (PCL's point cloud format, version 0.7).

Every PCD writer builds its header here: the scans (:func:`lidar.io.pcd.write_pcd`, :mod:`lidar.io.convert`)
and the clouds handed to PCL's programs (:mod:`registration.ndt`). Files are read by :mod:`lidar.io.pcd`.
"""
from __future__ import annotations

import numpy as np

#: The viewpoint of a cloud without a pose: at the origin, not rotated (tx ty tz qw qx qy qz).
NO_VIEWPOINT = "0 0 0 1 0 0 0"
_KINDS = {"f": "F", "i": "I", "u": "U"}


def binary_pcd_header(records: np.dtype, n: int, *, viewpoint: str = NO_VIEWPOINT) -> bytes:
    """The ASCII header of a binary PCD of ``n`` points whose records are of the structured type ``records``.

    Parameters
    ----------
    records : numpy structured dtype
        One field a PCD field (name, little-endian scalar type), packed, in file order.
    n : int
        Number of points (an unorganised cloud: ``WIDTH n``, ``HEIGHT 1``).
    viewpoint : str, keyword-only
        ``tx ty tz qw qx qy qz`` of the cloud's acquisition viewpoint. Default the origin, not rotated.

    Returns
    -------
    bytes
        The header up to and including ``DATA binary`` and its line break; the records follow it.
    """
    names = list(records.names or ())
    types = [records.fields[name][0] for name in names]  # type: ignore[index]
    return ("# .PCD v0.7 - written by BridgeSurvey\nVERSION 0.7\n"
            f"FIELDS {' '.join(names)}\nSIZE {' '.join(str(t.itemsize) for t in types)}\n"
            f"TYPE {' '.join(_KINDS[t.kind] for t in types)}\nCOUNT {' '.join('1' for _ in types)}\n"
            f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT {viewpoint}\nPOINTS {n}\nDATA binary\n").encode("ascii")

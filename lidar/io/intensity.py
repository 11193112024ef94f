"""Vendor intensity conventions: recognise them and normalise consistently.

Scanners and their software store intensity in different units:

===========================  ==============================  =====================
convention                   typical source                  normalised with
===========================  ==============================  =====================
``unit float 0-1``           Leica PTX, Cyclone, E57 exports  the fixed range 0..1
``declared limits``          E57 ``intensityLimits``          the declared range
``Riegl reflectance dB``     RiSCAN PRO (may be negative)     the file's dB range
``Leica PTS -2048..2047``    Cyclone PTS                      the file's range
``FARO 11-bit 0..2047``      FARO SCENE exports               the file's range
``8-bit 0..255``             many ASCII/PLY exports           the file's range
``16-bit 0..65535``          LAS/LAZ (the ASPRS convention)   the file's range
``float, file range``        anything else                    the file's range
===========================  ==============================  =====================

Every convention is mapped linearly (and monotonically) onto [0, 1] over the
range named above, so the brightest returns of any file are near 1 and
detection thresholds mean the same thing for every vendor. The convention and
the range used are written into the scan's metadata (``intensity_convention``,
``intensity_limits``); the raw values are kept unchanged.
"""
from __future__ import annotations

import numpy as np


def detect_convention(raw: np.ndarray, *, declared: tuple[float, float] | None = None
                      ) -> tuple[str, tuple[float, float] | None]:
    """Name the intensity convention of ``raw`` and the range to normalise over.

    Parameters
    ----------
    raw : (N,) array
        Intensity values as stored in the file (finite).
    declared : (lo, hi), optional
        A range the file itself declares (E57 ``intensityLimits``).

    Returns
    -------
    (name, limits)
        ``limits`` is None where the file's own minimum and maximum are used.

    Examples
    --------
    >>> detect_convention(np.array([0.1, 0.9]))
    ('unit float 0-1', (0.0, 1.0))
    >>> detect_convention(np.array([-12.5, 3.0]))[0]
    'Riegl reflectance dB'
    >>> detect_convention(np.array([0, 1800], dtype=np.int32))[0]
    'FARO 11-bit 0..2047'
    """
    if declared is not None:
        return "declared limits", (float(declared[0]), float(declared[1]))
    raw = np.asarray(raw)
    if raw.size == 0:
        return "none", None
    lo, hi = float(raw.min()), float(raw.max())
    integral = raw.dtype.kind in "iu" or bool(np.all(raw == np.round(raw)))
    if raw.dtype.kind == "f" and lo >= 0.0 and hi <= 1.0 and not integral:
        return "unit float 0-1", (0.0, 1.0)
    if integral:
        if lo < 0 and lo >= -2048 and hi <= 2047:
            return "Leica PTS -2048..2047", None
        if lo >= 0 and hi <= 255:
            return "8-bit 0..255", None
        if lo >= 0 and hi <= 2047:
            return "FARO 11-bit 0..2047", None
        if lo >= 0 and hi <= 65535:
            return "16-bit 0..65535", None
    elif lo < 0 and lo >= -60 and hi <= 60:
        return "Riegl reflectance dB", None
    return "float, file range", None

"""Column and property names other tools give to coordinates and intensity.

Names are compared without case and without the ``scalar_`` prefix
CloudCompare adds to its scalar fields, so ``X``, ``x`` and ``scalar_X`` are
all x, and ``Intensity``, ``scalar_Intensity``, ``I`` and ``reflectance`` are
all intensity.
"""
from __future__ import annotations

from collections.abc import Sequence

#: Aliases of each role, in order of preference (compared in lower case, ``scalar_`` removed).
ALIASES: dict[str, tuple[str, ...]] = {
    "x": ("x", "//x", "easting"),
    "y": ("y", "northing"),
    "z": ("z", "elevation", "height"),
    "intensity": ("intensity", "i", "reflectance", "amplitude", "remission", "int", "intensities"),
}


def canonical(name: str) -> str:
    """Lower-case name without CloudCompare's ``scalar_`` prefix or comment marks.

    >>> canonical("scalar_Intensity")
    'intensity'
    >>> canonical("//X")
    'x'
    """
    n = name.strip().lstrip("/#").strip().lower()
    return n[len("scalar_"):] if n.startswith("scalar_") else n


def find_column(names: Sequence[str], role: str) -> int | None:
    """Index of the column playing ``role`` (``x``, ``y``, ``z`` or ``intensity``), or None.

    >>> find_column(["X", "Y", "Z", "Intensity", "ReturnNumber"], "intensity")
    3
    >>> find_column(["x", "y", "z", "red"], "intensity") is None
    True
    """
    canon = [canonical(n) for n in names]
    for alias in ALIASES[role]:
        if alias in canon:
            return canon.index(alias)
    return None

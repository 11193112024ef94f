"""How many decimals a number is printed with, by its unit: the suffix of its column name, once for every output.

Tables people read give millimetres to 0.01 mm; files for scripts (CSV, JSON) to 0.001 mm, far below any
sigma the product reports, and never a float's 17 digits (``warning_mm`` 16.842105263157894).

>>> shown("warning_mm", 16.842105263157894), written("warning_mm", 16.842105263157894)
('16.84', 16.842)
>>> shown("scale_ppm", 5.4321), written("days_from_baseline", 14.0)
('5.4', 14.0)
"""
from __future__ import annotations

import math

#: Decimals of a column in a table people read, by the ending of its name.
SHOWN_DECIMALS = {"_mm": 2, "_ppm": 1}
#: Files for scripts carry this many more decimals than the tables.
WRITTEN_EXTRA = 1


def decimals(column: str) -> int | None:
    """The decimals of ``column`` in a table people read (None: no unit with a rule)."""
    return next((d for suffix, d in SHOWN_DECIMALS.items() if column.endswith(suffix)), None)


def shown(column: str, value: float) -> str | None:
    """``value`` of ``column`` as a table shows it, or None when its unit has no rule (or it is not finite)."""
    d = decimals(column)
    if d is None or not math.isfinite(value):
        return None
    text = f"{value:.{d}f}"
    return text.lstrip("-") if float(text) == 0 else text  # -0.001 mm is shown as 0.00, not -0.00


def written(column: str, value: object) -> object:
    """``value`` of ``column`` as a file for scripts holds it: rounded to its unit's decimals (others unchanged)."""
    d = decimals(column)
    if d is None or not isinstance(value, float) or not math.isfinite(value):
        return value
    return round(value, d + WRITTEN_EXTRA) + 0.0

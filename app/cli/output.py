"""Printing results: aligned tables for people, JSON for scripts."""
from __future__ import annotations

import json
import math
import sys
from collections.abc import Sequence

import numpy as np

from common.files import json_safe
from common.numbers import shown


def table(rows: Sequence[dict], columns: Sequence[str], out=None) -> None:
    out = out or sys.stdout
    if not rows:
        out.write("(none)\n")
        return
    def fmt(v, column):
        if isinstance(v, float):
            if math.isnan(v):
                return "-"
            fixed = shown(column, v)  # millimetres to 0.01 in every table (common.numbers)
            if fixed is not None:
                return fixed
            return f"{v:.4f}".rstrip("0").rstrip(".") if abs(v) < 1e5 else f"{v:.1f}"
        if isinstance(v, (list, tuple)):
            return ",".join(str(x) for x in v) or "-"
        return "-" if v is None or v == "" else str(v)
    cells = [[fmt(r.get(c), c) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    out.write("  ".join(c.ljust(w) for c, w in zip(columns, widths, strict=False)).rstrip() + "\n")
    for row in cells:
        out.write("  ".join(v.ljust(w) for v, w in zip(row, widths, strict=False)).rstrip() + "\n")


def dump_json(obj, out=None) -> None:
    out = out or sys.stdout

    def default(o):
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, (np.floating, np.integer)):
            return o.item()
        raise TypeError(f"not JSON serialisable: {type(o).__name__}")


    out.write(json.dumps(json_safe(obj), indent=2, default=default) + "\n")


def print_import(what: str, summ: dict) -> None:
    """The lines an import of a series prints: what was read, how the times were read, what was left out."""
    print(f"imported {what}: {summ['rows']} rows from {summ['start']} to {summ['end']}, column "
          f"'{summ['column']}' in {summ['unit_read']}, {summ['gaps']} gap(s), {summ['missing_values']} missing "
          f"value(s)")
    print(f"  times: {summ['times']}")
    if summ["bad_rows"]:
        print(f"  {summ['bad_rows']} bad row(s) of {summ['rows_in_file']} left out (could not be read):")
    for line in summ["first_bad_lines"][:5]:
        print(f"    {line}")
    if summ["bad_rows"] > 5:
        print(f"    ... and {summ['bad_rows'] - 5} more")
    for note in summ["notes"]:
        if "could not be read" not in note:
            print(f"  note: {note}")

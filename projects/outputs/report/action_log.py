"""The campaign's action log in words: one row per entry (time, epoch, action, files, result).

Each logged action (``Campaign._log``) gets a short phrase for what was done and what came of it, from
its details; an action this module does not know is shown as its details' ``key: value`` pairs, never as
raw JSON. File paths are shortened to their names (the full paths and checksums are in the scan-file
table and the workbook export).
"""
from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from projects.outputs.report.flowables import num
from projects.store.records import LogEntry


@dataclass(frozen=True)
class ActionRow:
    """One log entry as the report prints it."""

    time: str
    epoch: str
    action: str
    files: str
    result: str


def _files(v: Any) -> str:
    paths = v if isinstance(v, (list, tuple)) else ([v] if v else [])
    return ", ".join(os.path.basename(str(p)) for p in paths)


def _short_hash(v: Any) -> str:
    vals = v if isinstance(v, (list, tuple)) else [v]
    return ", ".join(str(x)[:12] + "…" for x in vals if x)


def _value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_value(x)}" for k, x in v.items())
    if isinstance(v, (list, tuple)):
        return ", ".join(_value(x) for x in v)
    return "–" if v is None else str(v)


def _pairs(d: dict) -> str:
    return "; ".join(f"{k.replace('_', ' ')}: {_value(v)}" for k, v in d.items())


def _target(rid: Any) -> str:
    return "every measurement target" if rid == "*" else str(rid)


def _count(n: Any, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _mm(v: Any, fmt: str = "{:.2f}") -> str:
    return "–" if not isinstance(v, (int, float)) else num(float(v), fmt)


_DESCRIBE: dict[str, Callable[[dict], tuple[str, str, str]]] = {
    "init": lambda d: ("campaign created", "", f"“{d.get('name', '')}”, {d.get('reflectors', '?')} reflectors"),
    "import": lambda d: (f"{d.get('role', '')} scan imported", _files(d.get("files")),
                         f"stored read-only, SHA-256 {_short_hash(d.get('sha256'))}"),
    "plan": lambda d: ("fine scans planned", "", f"plan stored (inputs {str(d.get('inputs_hash', ''))[:8]})"),
    "measure": lambda d: ("centroids measured", "", f"{d.get('found', '?')} targets found"),
    "displacements": lambda d: ("displacements computed", "", f"against baseline {d.get('baseline', '?')}"),
    "revisions": lambda d: ("stored values revised", "", f"{_count(len(d.get('revised', [])), 'value')}: "
                            + "; ".join(f"{r['epoch']} {r['target']} {r['old']} → {r['new']}"
                                        for r in d.get("revised", [])[:3])
                            + (" …" if len(d.get("revised", [])) > 3 else "")),
    "limit": lambda d: ("limit set", "", f"{_target(d.get('reflector'))}: {d.get('rule', '')}"),
    "setting": lambda d: ("setting changed", "", _pairs(d)),
    "scanner": lambda d: ("scanner chosen", "", str(d.get("name", ""))),
    "reflector-add": lambda d: ("reflector added", "", f"{d.get('id')} ({d.get('group')})"
                                + (f", replaces {d['replaces']}" if d.get("replaces") else "")),
    "reflector-retire": lambda d: ("reflector retired", "", f"{d.get('id')} from {str(d.get('when', ''))[:10]}"),
    "reflector-replace": lambda d: ("reflector replaced", "", f"{d.get('old')} by {d.get('new')} from "
                                                              f"{str(d.get('when', ''))[:10]}"),
    "camera-import": lambda d: ("camera series imported", _files(d.get("file")),
                                f"“{d.get('name')}”: {d.get('rows', 0):,} rows, {d.get('bad_rows', 0)} bad, "
                                f"paired with {d.get('reflector')}"),
    "crossval": lambda d: ("camera cross-validated", "",
                           f"“{d.get('series')}” against {d.get('reflector')}: {_count(d.get('n_pairs'), 'pair')}, bias "
                           f"{_mm(d.get('bias_mm'), '{:+.2f}')} mm, RMSE {_mm(d.get('rmse_mm'))} mm"),
    "env-import": lambda d: ("environment series imported", _files(d.get("file")),
                             f"{d.get('kind')} “{d.get('name')}”: {d.get('rows', 0):,} rows, {d.get('bad_rows', 0)} bad"),
    "event-add": lambda d: ("event added", "", f"{d.get('kind')} “{d.get('label')}” on "
                                               f"{str(d.get('date', ''))[:16].replace('T', ' ')}"),
    "prediction-import": lambda d: ("design prediction imported", _files(d.get("file")),
                                    f"targets {_value(d.get('targets'))}, aligned "
                                    + (f"at {d['align_at']}" if d.get("align_at") else "by least squares")),
    "compare": lambda d: ("whole-scan comparison", "", f"from {d.get('from')}, {str(d.get('method', '')).upper()}"),
}


def action_row(entry: LogEntry) -> ActionRow:
    """One log entry in words (an unknown action: its details as ``key: value`` pairs)."""
    d = dict(entry.details)
    describe = _DESCRIBE.get(entry.action)
    try:
        action, files, result = describe(d) if describe else (entry.action, _files(d.pop("file", d.pop("files", None))),
                                                               _pairs(d))
    except (KeyError, TypeError, ValueError):  # details of an older version: show them as they are
        action, files, result = entry.action, "", _pairs(entry.details)
    return ActionRow(entry.time[:19].replace("T", " "), entry.epoch or "", action, files, result)

"""Messages in the application's words (no Qt here).

The campaign code speaks to both front ends, and many of its messages name what to do next as a
command line (``run 'bridgesurvey process' first``, ``give another --name``). In the application the
same advice names the menu entry and the dialog field instead; :func:`in_app_words` rewrites a
message once, where the application shows it.

>>> in_app_words("epoch 'e1' already exists; use another --label or add-fine to add files to it")
"epoch 'e1' already exists; use another Label or Epoch ▸ Add fine scans to the selected epoch… to add files to it"
>>> in_app_words("no LiDAR displacements of M3 yet; run 'bridgesurvey process' first")
'no LiDAR displacements of M3 yet; use Epoch ▸ Process first'
"""
from __future__ import annotations

import re

#: Command-line commands -> the menu entry doing the same.
MENUS = {
    "add-epoch": "Epoch ▸ Add epoch…",
    "add-fine": "Epoch ▸ Add fine scans to the selected epoch…",
    "add-setup": "Epoch ▸ Add a set-up to the selected epoch…",
    "plan": "Epoch ▸ Plan the selected epoch",
    "check": "Epoch ▸ Check the fine scans before leaving",
    "process": "Epoch ▸ Process",
    "status": "the campaign tree",
    "init": "File ▸ New campaign…",
    "limit": "Campaign ▸ Set limit…",
    "settings": "Campaign ▸ Processing parameter…",
    "stations": "Campaign ▸ Where to stand…",
    "camera import": "Camera ▸ Import series…",
    "crossval": "Camera ▸ Cross-validate with LiDAR",
    "env import": "Analysis ▸ Import environment series…",
    "event add": "Analysis ▸ Add event…",
    "prediction import": "Analysis ▸ Import design prediction…",
    "report": "Reports ▸ Write report (PDF)…",
    "export": "Reports ▸ Export workbook (XLSX)…",
    "field-sheet": "Epoch ▸ Field sheet of the selected epoch (PDF)…",
    "verify": "Campaign ▸ Verify campaign",
    "repair": "Campaign ▸ Repair campaign",
}
#: Command-line options -> the dialog field (or setting) holding the same value.
FIELDS = {
    "label": "Label", "name": "Series name", "load-kn-m": "Load (kN/m)", "window-min": "Pairing window",
    "span-m": "Span, set in File ▸ New campaign…", "grid-m": "Grid", "ground-z": "Ground height", "column": "Value column",
    "unit": "Unit", "timezone": "Zone of times without offset", "kind": "Kind", "date": "Date",
    "rule": "Limit rule", "scanner": "Scanner (Campaign ▸ Scanner…)", "series": "Series",
    "align-at": "Align at", "workers": "Workers", "epoch": "the selected epoch",
    "setup": "the set-up added last", "pose": "Pose file", "origin": "Scanner position",
}
_COMMANDS = "|".join(sorted((re.escape(k) for k in MENUS), key=len, reverse=True))
_RUN = r"(?P<run>run\s+)?"
# 'bridgesurvey process' / 'bridgesurvey settings DIR casting_date 2017-09-16' / 'env import'
_QUOTED = re.compile(_RUN + r"'(?:bridgesurvey\s+)?(?P<cmd>" + _COMMANDS + r")(?:\s[^']*)?'")
# bridgesurvey limit DIR --rule ...
_SETTING = re.compile(r"'bridgesurvey settings DIR (?P<key>\w+)[^']*'")
_BARE = re.compile(_RUN + r"\bbridgesurvey\s+(?P<cmd>" + _COMMANDS + r")\b(?:\s+(?:[A-Z]+|--[a-z][\w-]*|\.\.\.))*")
_INIT_OPTION = re.compile(r"\binit\s+--(?P<opt>[a-z][a-z0-9-]*)")
_ADD_FINE = re.compile(r"(?<![\w-])add-fine\b")
_OPTION = re.compile(r"(?<![\w-])--(?P<opt>[a-z][a-z0-9-]*)")


def _menu(m: re.Match) -> str:
    return ("use " if m.group("run") else "") + MENUS[m.group("cmd")]


def _field(m: re.Match) -> str:
    return FIELDS.get(m.group("opt"), m.group("opt").replace("-", " "))


def in_app_words(message: str) -> str:
    """``message`` with command lines replaced by menu entries and options by dialog fields."""
    text = _SETTING.sub(lambda m: f"{MENUS['settings']} {m.group('key')}", message)
    text = _QUOTED.sub(_menu, text)
    text = _BARE.sub(_menu, text)
    text = _INIT_OPTION.sub(_field, text)
    text = _ADD_FINE.sub(MENUS["add-fine"], text)
    return _OPTION.sub(_field, text)


def windows_text(rois) -> str:
    """How many windows a plan has, the closure window told apart, in the same words everywhere.

    >>> from types import SimpleNamespace as R
    >>> windows_text([R(closure=False)] * 9 + [R(closure=True)])
    '9 windows + the closure window'
    >>> windows_text([R(closure=False)])
    '1 window'
    """
    n = sum(not r.closure for r in rois)
    text = f"{n} window{'' if n == 1 else 's'}"
    return text + (" + the closure window" if any(r.closure for r in rois) else "")

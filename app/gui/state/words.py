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
from pathlib import PurePath

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
    "archive": "Campaign ▸ Restore scans…",
}
#: Command-line options -> the dialog field (or setting) holding the same value.
FIELDS = {
    "label": "Label", "name": "Series name", "load-kn-m": "Load (kN/m)", "window-min": "Pairing window",
    "span-m": "Span, set in File ▸ New campaign…", "grid-m": "Grid", "ground-z": "Ground height", "column": "Value column",
    "unit": "Unit", "timezone": "Zone of times without offset", "kind": "Kind", "date": "Date",
    "rule": "Limit rule", "scanner": "Scanner (Campaign ▸ Scanner…)", "series": "Series",
    "align-at": "Align at", "workers": "Workers", "epoch": "the selected epoch",
    "setup": "the set-up added last", "pose": "Pose file", "origin": "Scanner position",
    "to": "the folder picker", "from": "Campaign ▸ Restore scans…, its folder",
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


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def archive_question(move, dest) -> str:
    """The question before archiving: what would move where, what it frees, the room there, what stays and why.

    ``move`` an :class:`app.gui.actions.StorageMove` of a dry run.

    >>> from types import SimpleNamespace as S
    >>> run = S(moved=[("scans/a.laz", "w1", 4_000_000, "/d/a.laz"), ("scans/b.laz", "w1", 1_000_000, "/d/b.laz")],
    ...         bytes=5_000_000, epochs=["w1"])
    >>> print(archive_question(S(run=run, size=9_000_000, free=100_000_000, left={"w2": "not measured yet"}), "/d"))
    Move 2 scan(s) of 1 visit(s) (5.0 MB) to /d? The campaign folder holds 9.0 MB; /d has 100.0 MB free.
    <BLANKLINE>
    Each scan is checked against its import checksum before it leaves the campaign; Campaign ▸ Restore scans… brings them back.
    <BLANKLINE>
    Not archived: w2: not measured yet
    """
    run = move.run
    room = "" if move.free is None else f"; {dest} has {_mb(move.free)} free" + (
        "" if move.free >= run.bytes else f": not enough, free {_mb(run.bytes - move.free)} more first")
    text = (f"Move {len(run.moved)} scan(s) of {len(run.epochs)} visit(s) ({_mb(run.bytes)}) to {dest}? The campaign "
            f"folder holds {_mb(move.size)}{room}.\n\nEach scan is checked against its import checksum before it "
            "leaves the campaign; Campaign ▸ Restore scans… brings them back.")
    return text + _left(move.left)


def _left(left: dict) -> str:
    if not left:
        return ""
    lines = [f"{label}: {in_app_words(why)}" for label, why in list(left.items())[:5]]
    more = f"\n… and {len(left) - 5} more" if len(left) > 5 else ""
    return "\n\nNot archived: " + "\n".join(lines) + more


def nothing_to_archive(move) -> str:
    """Why an archive run would move nothing."""
    return "Nothing to archive: every processed visit's scans are archived already." if not move.left else \
        "Nothing to archive." + _left(move.left)


def restore_question(move) -> str:
    """The question before bringing archived scans back (``move`` a dry run's :class:`app.gui.actions.StorageMove`).

    >>> from types import SimpleNamespace as S
    >>> run = S(moved=[("scans/a.laz", "w1", 4_000_000, "/d/a.laz")], bytes=4_000_000, epochs=["w1"])
    >>> print(restore_question(S(run=run, free=None)))
    Bring back 1 scan(s) of 1 visit(s) (4.0 MB) from /d into the campaign folder? Each is checked against its import checksum.
    """
    run = move.run
    places = ", ".join(dict.fromkeys(str(PurePath(m[3]).parent) for m in run.moved))
    room = "" if move.free is None or move.free >= run.bytes else \
        f" The campaign's disk has {_mb(move.free)} free: not enough, free {_mb(run.bytes - move.free)} more first."
    return (f"Bring back {len(run.moved)} scan(s) of {len(run.epochs)} visit(s) ({_mb(run.bytes)}) from {places} into "
            f"the campaign folder? Each is checked against its import checksum.{room}")

"""Many bridges: find every campaign under some folders (or in a fleet file) and summarise each.

A fleet file is a text file listing campaign folders (or folders holding campaigns), one per line,
relative to the file; ``#`` starts a comment.
"""
from __future__ import annotations

import datetime as dt
import os
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from common.errors import InputError, SurveyError
from projects.results.status import campaign_status
from projects.series.camera import crossval_summaries
from projects.store.campaign import DB_NAME, Campaign

MAX_DEPTH = 8
STATE_ORDER = ("alarm", "warning", "ok", "unknown")


def _read_fleet_file(path: Path) -> list[Path]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the fleet file ({exc})") from None
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            p = Path(line)
            out.append(p if p.is_absolute() else (path.parent / p))
    if not out:
        raise InputError(f"{path}: the fleet file lists no folder")
    return out


def find_campaigns(roots: Sequence[str | os.PathLike]) -> list[Path]:
    """Every campaign folder under ``roots`` (folders, campaign folders or fleet files), sorted, once each.

    A folder a fleet file lists that does not exist is an error here (see :func:`survey_roots`).
    """
    found, missing = survey_roots(roots)
    if missing:
        raise InputError(f"{missing[0][0]}: no such folder (listed in {missing[0][1]})")
    return found


def survey_roots(roots: Sequence[str | os.PathLike]) -> tuple[list[Path], list[tuple[Path, Path]]]:
    """The campaign folders under ``roots``, and the folders fleet files list that do not exist.

    Returns ``(campaigns sorted, once each; [(missing folder, the fleet file listing it)])``. A root given
    itself that is neither a folder nor a fleet file is an :class:`InputError` (a mistake on the command
    line); a missing folder listed in a fleet file is a bridge that cannot be read today, not a reason to
    stop looking at the others.
    """
    if not roots:
        raise InputError("give at least one folder (or fleet file) to look for campaigns in")
    found: dict[str, Path] = {}
    queue: list[Path] = []
    missing: list[tuple[Path, Path]] = []
    for r in roots:
        p = Path(r)
        if p.is_file():
            for listed in _read_fleet_file(p):
                if listed.is_dir():
                    queue.append(listed)
                else:
                    missing.append((listed, p))
        elif p.is_dir():
            queue.append(p)
        else:
            raise InputError(f"{p}: no such folder or fleet file")
    seen: set[str] = set()  # folders walked, resolved: a link back up the tree is walked once
    for root in queue:
        base = len(root.parts)
        # a campaign folder may be a link (a bridge's folder kept on another disk): links are followed
        for dirpath, dirnames, filenames in os.walk(root, followlinks=True):
            here = Path(dirpath)
            real = str(here.resolve())
            if real in seen:
                dirnames[:] = []
                continue
            seen.add(real)
            if DB_NAME in filenames:
                found.setdefault(real, here)
                dirnames[:] = []  # a campaign's own folders hold no campaign
                continue
            dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and
                                 len(Path(dirpath, d).parts) - base <= MAX_DEPTH)
    return sorted(found.values(), key=lambda p: str(p)), missing


@dataclass(frozen=True)
class BridgeStatus:
    """One bridge of the fleet, as ``fleet status`` shows it."""

    folder: str
    name: str
    epochs: int = 0
    last_epoch: str | None = None
    last_date: str | None = None
    days_since: int | None = None
    work_left: int = 0
    state: str = "unknown"
    worst_target: str | None = None
    worst_displacement_mm: float | None = None
    worst_limit_mm: float | None = None
    worst_ratio: float | None = None
    problems: int = 0
    crossval: list = field(default_factory=list)
    analysis: str | None = None
    error: str | None = None

    def to_json(self) -> dict:
        return asdict(self)


def _days_since(iso: str, today: dt.date) -> int:
    return (today - dt.date.fromisoformat(iso[:10])).days


def bridge_status(folder: str | os.PathLike, *, today: dt.date | None = None) -> BridgeStatus:
    """Summary of one campaign, read-only; an unreadable campaign gets its one-line error instead."""
    folder = Path(folder)
    today = today or dt.date.today()
    try:
        with Campaign.open(folder, writable=False) as c:
            data = campaign_status(c)
            crossval = [{k: v for k, v in s.items() if k in ("series", "bias_mm", "rmse_mm", "correlation", "n_pairs")}
                        for s in crossval_summaries(c)]
    except SurveyError as exc:
        return BridgeStatus(str(folder), folder.name, error=str(exc).splitlines()[0])
    epochs = data["epochs"]
    last = epochs[-1] if epochs else None
    worst, worst_key = None, (-1, -1.0)
    for t in data["targets"]:
        state = t.get("state") or "unknown"
        rank = {"alarm": 3, "warning": 2, "ok": 1}.get(state, 0)
        disp, lim = t.get("displacement_mm"), t.get("alarm_mm")
        ratio = abs(disp) / lim if disp is not None and lim else -1.0
        if (rank, ratio) > worst_key:
            worst, worst_key = t, (rank, ratio)
    analysis = folder / "analysis" / "analysis.json"
    return BridgeStatus(
        str(folder), data["name"], len(epochs), last["epoch"] if last else None,
        last["datetime"][:10] if last else None, _days_since(last["datetime"], today) if last else None,
        sum(1 for e in epochs if e["stale"]),
        {3: "alarm", 2: "warning", 1: "ok"}.get(worst_key[0], "unknown"),
        worst["reflector"] if worst else None,
        worst.get("displacement_mm") if worst else None,
        worst.get("alarm_mm") if worst else None,
        round(worst_key[1], 3) if worst_key[1] >= 0 else None,
        sum(1 for e in epochs if e["state"] == "problem"), crossval,
        str(analysis) if analysis.is_file() else None)


def fleet_status(roots: Sequence[str | os.PathLike], *, today: dt.date | None = None,
                 overdue_days: int = 10) -> dict:
    """Every bridge's status plus an overview (counts by state, overdue bridges, work left).

    A campaign that cannot be read, or a folder a fleet file lists that is not there, is a bridge with
    its one-line ``error`` (unreadable), listed first; the others are summarised as usual.
    """
    folders, missing = survey_roots(roots)
    bridges = [bridge_status(f, today=today) for f in folders]
    bridges += [BridgeStatus(str(f), f.name, error=f"no such folder (listed in {listing})") for f, listing in missing]
    order = {s: k for k, s in enumerate(STATE_ORDER)}
    bridges.sort(key=lambda b: (b.error is None, order.get(b.state, 9), -(b.worst_ratio or 0), b.name))
    return {"bridges": [b.to_json() for b in bridges],
            "overview": {"bridges": len(bridges), **{s: sum(b.state == s for b in bridges) for s in STATE_ORDER},
                         "unreadable": sum(b.error is not None for b in bridges),
                         "overdue": [b.name for b in bridges if b.days_since is not None and b.days_since > overdue_days],
                         "overdue_days": overdue_days,
                         "work_left": sum(b.work_left for b in bridges)}}


def iter_names(status: dict) -> Iterable[str]:
    """The bridge names of a fleet status document."""
    return (b["name"] for b in status["bridges"])

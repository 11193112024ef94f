"""The campaign a command names (``DIR``) and the set-up of a visit it asks for (``--setup``)."""
from __future__ import annotations

from pathlib import Path

from projects.store.campaign import Campaign


def open_campaign(path: Path, writable: bool = True) -> Campaign:
    """The campaign in folder ``path`` (read-only with ``writable=False``)."""
    return Campaign.open(path, writable=writable)


def setup_of(c, args) -> int:
    """The set-up ``--setup`` names (checked), or the epoch's last one."""
    return c.check_setup(args.epoch, args.setup) if args.setup is not None else c.last_setup(args.epoch)


def setup_date(c, label: str, setup: int) -> str:
    """The epoch's date as a field sheet names it (with the set-up when the visit has several)."""
    date = c.epoch(label).date
    return f"{date}, set-up {setup}" if len(c.setups(label)) > 1 else date

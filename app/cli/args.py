"""What the commands' parsers share: the campaign folder, --epoch and --json, checked paths, lazy choices.

Building the parser must stay fast (``bridgesurvey --help`` in a fraction of a second): nothing here, nor in
any ``register`` function, imports numpy, pandas, scipy, Qt or the processing code. Choice lists that live
in heavy modules come through :class:`LazyChoices`, loaded only when a command's help or value check
needs them.
"""
from __future__ import annotations

import argparse
import importlib
import os
import textwrap
import weakref
from collections.abc import Iterator, Sequence
from pathlib import Path

from common.errors import InputError

#: The positional DIR of every campaign command (explained once in the top-level help too).
DIR_HELP = "the campaign folder: the one 'bridgesurvey init' created (it holds campaign.sqlite and the imported scans)"
DIR_EXPLAINED = ("DIR is a campaign folder, one per bridge: 'bridgesurvey init DIR ...' creates it, and every "
                 "campaign command takes it first (bridgesurvey status DIR). It holds campaign.sqlite, the "
                 "imported scans (copied in once, never modified) and nothing else you need to touch.")
EPOCH_HELP = "the epoch's label (its date, e.g. 2026-03-02, unless 'add-epoch --label' gave another)"
JSON_HELP = "print JSON for scripts instead of a table"

OUTPUT_FILE, OUTPUT_FOLDER, INPUT_FILE, INPUT_FOLDER = "output file", "output folder", "input file", "input folder"
PATH_KINDS = (OUTPUT_FILE, OUTPUT_FOLDER, INPUT_FILE, INPUT_FOLDER)

#: The checked path options: action -> (kind, suffixes). Weak keys: tests build many parsers.
_CHECKED: weakref.WeakKeyDictionary[argparse.Action, tuple[str, tuple[str, ...]]] = weakref.WeakKeyDictionary()


class HelpFormatter(argparse.HelpFormatter):
    """argparse's help layout, never breaking a word at its hyphen ('add-epoch', 'plan-file')."""

    def _split_lines(self, text, width):
        text = " ".join(text.split())
        return textwrap.wrap(text, width, break_on_hyphens=False, break_long_words=False)

    def _fill_text(self, text, width, indent):
        text = " ".join(text.split())
        return textwrap.fill(text, width, initial_indent=indent, subsequent_indent=indent, break_on_hyphens=False,
                             break_long_words=False)


class RawDescriptionHelpFormatter(argparse.RawDescriptionHelpFormatter, HelpFormatter):
    """A description laid out as written; option help as :class:`HelpFormatter`."""


def mark(action: argparse.Action, kind: str, suffixes: Sequence[str] = ()) -> argparse.Action:
    """Have :func:`check_paths` check ``action``'s value(s) as a path of ``kind`` (one of :data:`PATH_KINDS`)."""
    if kind not in PATH_KINDS:
        raise ValueError(f"unknown path kind {kind!r}")
    _CHECKED[action] = (kind, tuple(s.lower() for s in suffixes))
    return action


def path_kind(action: argparse.Action) -> str | None:
    """The kind :func:`mark` gave ``action`` (None for an unchecked option)."""
    entry = _CHECKED.get(action)
    return entry[0] if entry else None


def add_dir(p: argparse.ArgumentParser) -> argparse.Action:
    """The positional campaign folder DIR."""
    return p.add_argument("dir", type=Path, metavar="DIR", help=DIR_HELP)


def add_epoch(p: argparse._ActionsContainer, *, required: bool = True, help: str = EPOCH_HELP, **kw) -> argparse.Action:
    """The ``--epoch LABEL`` option (``kw``: more of ``add_argument``'s, e.g. ``action="append"``)."""
    return p.add_argument("--epoch", required=required, metavar="LABEL", help=help, **kw)


def add_json(p: argparse.ArgumentParser, help: str = JSON_HELP) -> argparse.Action:
    """The ``--json`` switch."""
    return p.add_argument("--json", action="store_true", help=help)


def output_file(p: argparse.ArgumentParser, *flags: str, help: str, suffixes: Sequence[str] = (),
                **kw) -> argparse.Action:
    """An option naming a file to write, checked before the command starts (see :func:`check_paths`)."""
    kw.setdefault("metavar", "FILE")
    return mark(p.add_argument(*flags, type=Path, help=help, **kw), OUTPUT_FILE, suffixes)


def output_folder(p: argparse.ArgumentParser, *flags: str, help: str, **kw) -> argparse.Action:
    """An option (or positional) naming a folder to write into, created when missing, checked before starting."""
    kw.setdefault("metavar", "FOLDER")
    return mark(p.add_argument(*flags, type=Path, help=help, **kw), OUTPUT_FOLDER)


def input_file(p: argparse.ArgumentParser, *flags: str, help: str, **kw) -> argparse.Action:
    """An option (or positional) naming file(s) to read, checked before the command starts."""
    kw.setdefault("metavar", "FILE")
    return mark(p.add_argument(*flags, type=Path, help=help, **kw), INPUT_FILE)


def input_folder(p: argparse.ArgumentParser, *flags: str, help: str, **kw) -> argparse.Action:
    """An option naming a folder to read from, checked before the command starts."""
    kw.setdefault("metavar", "FOLDER")
    return mark(p.add_argument(*flags, type=Path, help=help, **kw), INPUT_FOLDER)


def check_input(path: Path, *, folder: bool = False) -> None:
    """Refuse, in one line, an input that is missing, of the wrong kind (a folder for a file) or unreadable."""
    if not path.exists():
        raise InputError(f"{path}: no such {'folder' if folder else 'file'}; check the path")
    if folder and not path.is_dir():
        raise InputError(f"{path}: is a file; give the folder that holds the files")
    if not folder and path.is_dir():
        raise InputError(f"{path}: is a folder, not a file; give the file itself")
    if not os.access(path, os.R_OK | (os.X_OK if folder else 0)):
        raise InputError(f"{path}: no permission to read it")


def check_paths(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Check every marked path option of ``parser`` (the command being run), inputs first, then outputs."""
    from common.files import check_output  # local: csv, hashlib, tempfile: 0.11 s of every command's start (importtime)

    checked = [(a, _CHECKED[a]) for a in parser._actions if a in _CHECKED]
    checked.sort(key=lambda item: item[1][0].startswith("output"))
    for action, (kind, suffixes) in checked:
        value = getattr(args, action.dest, None)
        for path in value if isinstance(value, list) else [value]:
            if path is None:
                continue
            if kind in (INPUT_FILE, INPUT_FOLDER):
                check_input(Path(path), folder=kind == INPUT_FOLDER)
            else:
                check_output(path, folder=kind == OUTPUT_FOLDER, suffixes=suffixes)


class LazyChoices(Sequence[str]):
    """The choices of an option, read from ``module``'s ``attribute`` the first time they are needed.

    Give the option a ``metavar``: argparse then reads the choices only to check a value or to print
    that command's help, never while the parser is built.
    """

    def __init__(self, module: str, attribute: str):
        self._where = (module, attribute)
        self._items: tuple[str, ...] | None = None

    def _load(self) -> tuple[str, ...]:
        if self._items is None:
            self._items = tuple(getattr(importlib.import_module(self._where[0]), self._where[1]))
        return self._items

    def __getitem__(self, index):  # type: ignore[override]
        return self._load()[index]

    def __len__(self) -> int:
        return len(self._load())

    def __iter__(self) -> Iterator[str]:
        return iter(self._load())

    def __contains__(self, value: object) -> bool:
        return value in self._load()

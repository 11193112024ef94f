"""Entry point of the ``bridgesurvey`` command.

Every command is registered by a module of this package and listed in the help in the order of a
visit (:data:`COMMAND_GROUPS`). Before a command runs, every path it will read or write is checked
(:func:`app.cli.args.check_paths`): a mistake gets one line before any computing. Errors the product
raises on purpose (``SurveyError``) are printed as one line and give exit status 1; wrong arguments give
status 2 with the usage of the command they were given to.

Building the parser imports no numpy, pandas, scipy, Qt or processing code (the commands import what
they need when they run): ``bridgesurvey --help`` and a refused command start in a fraction of a second.
"""
from __future__ import annotations

import argparse
import difflib
import gc
import importlib
import logging
import os
import shutil
import sys
import textwrap
from collections.abc import Sequence

from app.cli.args import (
    DIR_EXPLAINED,
    DIR_HELP,
    OUTPUT_FILE,
    OUTPUT_FOLDER,
    HelpFormatter,
    RawDescriptionHelpFormatter,
    check_paths,
    mark,
)
from common.errors import SurveyError

EXIT_ERROR = 1

DESCRIPTION = "Long-term bridge displacement from weekly terrestrial laser scans of reflector targets."

#: The commands in the order of the work, by group, as the top-level help lists them.
COMMAND_GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("set-up, once per bridge", ("init", "reflector", "limit", "settings", "demo")),
    ("each visit, in this order", ("add-epoch", "add-setup", "plan", "field-sheet", "add-fine", "check", "process")),
    ("results", ("status", "displacements", "report", "export")),
    ("the campaign's files: when something goes wrong, and old scans", ("verify", "repair", "archive")),
    ("analysis and cross-checks", ("compare", "env", "event", "prediction", "analyse", "camera", "crossval")),
    ("in the field: the instrument and where to stand", ("scanners", "stations")),
    ("scan and image files, outside a campaign", ("info", "convert", "detect", "plan-file", "centroids", "simulate",
                                                   "dualcam")),
    ("many bridges", ("fleet",)),
)

#: The group of each command: ``app.cli.parsers.GROUP`` registers its parser, ``app.cli.commands_GROUP`` holds the
#: function that runs it. A command given on the line is parsed by a parser of its group's commands only (importing
#: and building all of them took 0.02-0.03 s of every command's start); its functions' module, which imports what the
#: commands need at its top, is imported when the command runs (see :func:`command_function`).
COMMAND_MODULES: dict[str, str] = {
    **dict.fromkeys(("init", "reflector", "limit", "settings", "demo", "add-epoch", "add-setup", "plan", "add-fine",
                     "process", "status", "displacements", "export"), "campaign"),
    **dict.fromkeys(("field-sheet", "check", "stations"), "field"),
    "scanners": "scanners",
    "report": "report",
    **dict.fromkeys(("env", "event", "prediction", "analyse"), "analysis"),
    "compare": "compare",
    **dict.fromkeys(("camera", "crossval"), "camera"),
    **dict.fromkeys(("info", "convert"), "scanfiles"),
    **dict.fromkeys(("detect", "plan-file", "centroids", "simulate"), "files"),
    "dualcam": "dualcam",
    "fleet": "fleet",
    **dict.fromkeys(("verify", "repair", "archive"), "store"),
}

#: The commands over scan and image files: their work is the product's own loops (compiled, on two threads) and
#: numpy's, with no large matrix products. OpenBLAS's thread pool does nothing for them, and its threads spin on
#: a core for about 0.1 s after numpy loads (75 ms of CPU measured), time the commands' own threads need.
SINGLE_THREADED_BLAS = frozenset(dict(COMMAND_GROUPS)["scan and image files, outside a campaign"])

#: Path options of commands whose parsers another module owns: (command, dest) -> kind, checked like the rest.
FOREIGN_PATHS = {("compare", "out"): OUTPUT_FOLDER, ("plan-file", "out"): OUTPUT_FILE,
                 ("plan-file", "png"): OUTPUT_FILE, ("convert", "output"): OUTPUT_FILE}


class Parser(argparse.ArgumentParser):
    """An argument parser whose sub-commands record their one-line help and get a description from it."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self.register("action", "parsers", CommandParsers)


class CommandParsers(argparse._SubParsersAction):
    """Sub-command registry: remembers each command's help, defaults its description to that help."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.helps: dict[str, str] = {}

    def add_parser(self, name, **kwargs):
        text = kwargs.get("help")
        if text:
            self.helps[name] = text
            kwargs.setdefault("description", text[0].upper() + text[1:] + ("" if text.endswith((".", "?")) else "."))
        return super().add_parser(name, **kwargs)


def _command_list(helps: dict[str, str], width: int) -> str:
    grouped = [name for _, names in COMMAND_GROUPS for name in names]
    groups = list(COMMAND_GROUPS) + [("other", tuple(n for n in helps if n not in grouped))]
    col = 4 + max(len(n) for n in helps) + 2
    lines = ["commands, in the order of the work:"]
    for title, names in groups:
        names = tuple(n for n in names if n in helps)
        if not names:
            continue
        lines.append(f"  {title}")
        for n in names:
            wrapped = textwrap.wrap(helps[n], max(30, width - col), break_on_hyphens=False) or [""]
            lines.append(f"    {n.ljust(col - 4)}{wrapped[0]}")
            lines += [" " * col + w for w in wrapped[1:]]
    return "\n".join(lines)


def _walk(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    """Every parser of the tree with its command path (('',) for the top, ('fleet', 'status'), ...)."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _walk(sub, path + (name,))


def _finish(parser: argparse.ArgumentParser) -> None:
    """Explain every campaign DIR, check the foreign commands' paths, and let each parser be found from its args."""
    for path, p in _walk(parser):
        p.set_defaults(_parser=p)
        for action in p._actions:
            if action.dest == "dir" and not action.option_strings and action.help is None:
                action.help, action.metavar = DIR_HELP, "DIR"
            kind = FOREIGN_PATHS.get((path[0] if path else "", action.dest))
            if kind is not None and len(path) == 1:
                mark(action, kind)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``bridgesurvey`` parser with every command, or only ``command``'s module's (imports nothing heavy)."""
    width = min(100, shutil.get_terminal_size((100, 24)).columns) - 2
    parser = Parser(prog="bridgesurvey", usage="bridgesurvey [-h] [-v] COMMAND [DIR] [OPTIONS]",
                    formatter_class=RawDescriptionHelpFormatter,
                    epilog="Run 'bridgesurvey COMMAND --help' for what a command does and its options.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log what is being done")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", help=argparse.SUPPRESS, prog="bridgesurvey")
    sub.required = True
    if command in COMMAND_MODULES:
        modules = [COMMAND_MODULES[command]]
    else:
        modules = list(dict.fromkeys(COMMAND_MODULES.values()))  # each once, in the table's order
    for name in modules:
        importlib.import_module(f"app.cli.parsers.{name}").register(sub)
    _finish(parser)
    fill = lambda text: textwrap.fill(text, width, break_on_hyphens=False)  # noqa: E731
    parser.description = "\n\n".join((fill(DESCRIPTION), _command_list(sub.helps, width), fill(DIR_EXPLAINED)))
    return parser


def command_function(args: argparse.Namespace):
    """The function that runs the parsed command (the parser names it in ``func``), from its group's module.

    The module is imported here, only for the command that runs: the command modules import numpy, the store and
    the processing at their tops, which ``bridgesurvey --help`` and a refused command never need (they start in
    0.08 s; importing every command module would make it about 2 s).
    """
    module = importlib.import_module(f"app.cli.commands_{COMMAND_MODULES[args.command]}")
    return getattr(module, args.func)


def _command_of(argv: Sequence[str]) -> str | None:
    """The command named on a command line (its first word that is not an option), if any."""
    return next((word for word in argv if not word.startswith("-")), None)


def _refuse_unknown(parser: argparse.ArgumentParser, extra: Sequence[str]) -> None:
    """An unknown argument, reported with the usage of the command it was given to (exit 2)."""
    options = [s for a in parser._actions for s in a.option_strings]
    hint = ""
    for word in extra:
        close = difflib.get_close_matches(word.split("=", 1)[0], options, n=1) if word.startswith("-") else []
        if close:
            hint = f" (did you mean {close[0]}?)"
            break
    parser.error(f"unrecognized arguments: {' '.join(extra)}{hint}")


def _actions_of(parser: argparse.ArgumentParser, command: str) -> dict[str, argparse.ArgumentParser]:
    """The actions of ``command`` (``env`` -> import, list), or {} for a command without actions."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            sub = action.choices[command]
            return next((dict(a.choices) for a in sub._actions if isinstance(a, argparse._SubParsersAction)), {})
    return {}


def action_first(parser: argparse.ArgumentParser, argv: Sequence[str]) -> list[str]:
    """``argv`` in the one order of commands with actions, ``COMMAND ACTION DIR ...``, with a hint when swapped.

    Every command with actions takes its action right after its name (``env import DIR FILE``, ``fleet status
    ROOT``, ``reflector list DIR``). The other order (``reflector DIR list``) is read as the same command; a line
    on stderr shows the order to use.
    """
    argv = list(argv)
    words = [i for i, w in enumerate(argv) if not w.startswith("-")]
    if len(words) < 3:
        return argv
    command, first, second = (argv[i] for i in words[:3])
    actions = _actions_of(parser, command)
    if not actions or first in actions or second not in actions or words[2] != words[1] + 1:
        return argv
    argv.insert(words[1], argv.pop(words[2]))
    rest = " ".join(argv[words[1] + 1:])
    print(f"bridgesurvey: note: the action comes first: bridgesurvey {command} {second} {rest}", file=sys.stderr)
    return argv


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_of(argv))
    argv = action_first(parser, argv)
    args, extra = parser.parse_known_args(argv)
    command_parser = getattr(args, "_parser", parser)
    if extra:
        _refuse_unknown(command_parser, extra)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    if not args.verbose:  # a damaged LAZ: laspy logs its own ERROR line before the one line we print
        logging.getLogger("laspy").setLevel(logging.CRITICAL)
    if args.command in SINGLE_THREADED_BLAS:  # read when numpy loads: the command imports it later
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    try:
        check_paths(command_parser, args)
        return int(command_function(args)(args) or 0)
    except SurveyError as exc:
        print(f"bridgesurvey: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("bridgesurvey: interrupted", file=sys.stderr)
        return 130
    except (FileNotFoundError, PermissionError) as exc:
        # The last resort for what the system refused under the command's feet (a campaign folder moved, renamed
        # or made read-only while it ran): one line, never a traceback. Each store write says it better itself.
        where = f"{exc.filename}: " if exc.filename else ""
        what = "no longer there" if isinstance(exc, FileNotFoundError) else "permission denied"
        print(f"bridgesurvey: error: {where}{what}; was the folder moved, renamed or made read-only while the command "
              "ran? Nothing was committed that is not whole: run the command again where the folder is now",
              file=sys.stderr)
        return EXIT_ERROR
    except BrokenPipeError:
        # The reader went away (e.g. 'bridgesurvey status DIR | head'): stop quietly like other CLIs.
        # Point stdout at /dev/null so the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


def run() -> None:
    """The ``bridgesurvey`` program: :func:`main` on the command line, then exit with its status.

    The objects left when the command is done are frozen out of the garbage collector first: the
    interpreter's collections at exit traversed all of them again (numpy's and the product's modules),
    0.03-0.045 s of every command, for memory the system takes back anyway.
    """
    status = main()
    gc.freeze()
    sys.exit(status)


if __name__ == "__main__":  # pragma: no cover
    run()

"""Entry point of the ``bridgesurvey`` command.

Every command is registered by a module of this package; errors the product
raises on purpose (``SurveyError``) are printed as one line and give exit
status 1; wrong arguments give status 2 (argparse).
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from typing import Optional, Sequence

from common.errors import SurveyError

EXIT_ERROR = 1


def build_parser() -> argparse.ArgumentParser:
    from app.cli import (commands_analysis, commands_camera, commands_campaign, commands_compare, commands_dualcam,
                         commands_field, commands_files, commands_fleet, commands_report, commands_scanfiles)

    parser = argparse.ArgumentParser(
        prog="bridgesurvey",
        description="Long-term bridge displacement from weekly terrestrial laser scans of reflector targets.",
        epilog="Run 'bridgesurvey COMMAND --help' for the options of a command.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log what is being done")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for module in (commands_campaign, commands_compare, commands_camera, commands_dualcam, commands_report,
                   commands_files, commands_scanfiles, commands_field, commands_fleet, commands_analysis):
        module.register(sub)
    from app.cli import commands_store  # verify, repair
    commands_store.register(sub)
    return parser


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return int(args.func(args) or 0)
    except SurveyError as exc:
        print(f"bridgesurvey: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("bridgesurvey: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (e.g. 'bridgesurvey status DIR | head'): stop quietly like other CLIs.
        # Point stdout at /dev/null so the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""The parser of the ``scanners`` command (the scanner catalogue), run by app.cli.commands_scanners."""
from __future__ import annotations

from app.cli.args import add_json


def register(sub) -> None:
    p = sub.add_parser("scanners", help="the scanner catalogue: what each instrument offers, with sources",
                       description="Without NAME: list the catalogue. With NAME (or a profile .json): every value "
                                   "of that profile and where it came from. Choose one with 'init --scanner' or "
                                   "'settings DIR scanner NAME'.")
    p.add_argument("name", nargs="?", help="a scanner of the catalogue (quoted: \"Leica RTC360\") or a profile .json")
    add_json(p, help="print the catalogue (or the profile) as JSON")
    p.set_defaults(func="cmd_scanners")

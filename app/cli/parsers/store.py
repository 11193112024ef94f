"""The parsers of store commands: verify a campaign end to end, and repair what a restore or damage left.

They name each command's function in app.cli.commands_store (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import add_dir, add_json


def register(sub) -> None:
    p = sub.add_parser("verify", help="check the database, every imported file and every stored result",
                       description="Checks the database (integrity_check), every imported file against the checksum "
                                   "recorded at its import, files the database does not list, every stored result "
                                   "against the checksum stored with it, and whether the results match their "
                                   "inputs. Changes nothing. Each problem is one line with what to do; exit status 3 "
                                   "when there is any.")
    add_dir(p)
    add_json(p)
    p.set_defaults(func="cmd_verify")

    p = sub.add_parser("repair", help="register again the files the database lost; never deletes anything",
                       description="Sets a damaged schema version from the tables; registers again every file in "
                                   "scans/, camera/, environment/ and prediction/ that the database does not list "
                                   "(an older campaign.sqlite restored over a newer folder) when its checksum and "
                                   "header still match its import; reads damaged series again from their files. "
                                   "Damaged results are recomputed by 'process'. Says what it did.")
    add_dir(p)
    add_json(p)
    p.set_defaults(func="cmd_repair")

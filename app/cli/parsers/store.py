"""The parsers of store commands: verify a campaign end to end, repair what a restore or damage left, archive scans.

They name each command's function in app.cli.commands_store (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from pathlib import Path

from app.cli.args import add_dir, add_epoch, add_json


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

    p = sub.add_parser("archive", help="move the scans of processed visits to another disk, or bring them back",
                       description="Moves the scans of every fully processed visit (each set-up measured with the "
                                   "current parameters, displacements up to date) out of the campaign folder into "
                                   "DEST (e.g. another disk): each is copied, flushed to disk, checked against the "
                                   "checksum taken at its import, recorded in the campaign with its new place, then "
                                   "removed with its link under scans/by-visit/. Prints what it moved and the space "
                                   "freed. Stage 2, status, displacements and the reports keep working without the "
                                   "scans; processing a visit again after a stage-1 parameter changed, compare, the "
                                   "3-D view and inspect need them back: they stop that visit in one line naming the "
                                   "scans and where they are. 'archive DIR --restore' brings them back, checked ('--from "
                                   "FOLDER' when the archive disk is mounted somewhere else now). Run "
                                   "it again after an interruption: it finishes what was begun.")
    add_dir(p)
    p.add_argument("--to", type=Path, metavar="DEST", dest="to",
                   help="the folder to move the scans into: it must exist, be writable, be outside the campaign "
                        "folder and have room for them")
    p.add_argument("--before", metavar="DATE",
                   help="only visits dated before this date (ISO 8601, e.g. 2026-01-01)")
    p.add_argument("--restore", action="store_true",
                   help="bring archived scans back into the campaign folder (all, or those of --epoch), checked "
                        "against their checksums; the archived copies are then removed")
    p.add_argument("--from", type=Path, metavar="FOLDER", dest="source",
                   help="with --restore: the folder the archive disk is mounted at now, when the place the campaign "
                        "recorded cannot be reached (another computer, another mount point); each scan found there "
                        "is checked against the checksum taken at its import and its new place recorded before it "
                        "is copied back")
    add_epoch(p, required=False, help="with --restore: only this epoch's scans (its label)")
    p.add_argument("--dry-run", action="store_true", help="only say what would be moved, and the space it frees")
    add_json(p)
    p.set_defaults(func="cmd_archive")

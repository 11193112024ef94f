"""The parsers of the ``report`` command: a PDF survey report of one visit, a period or the whole campaign.

They name each command's function in app.cli.commands_report (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import add_dir, add_epoch, output_file


def register(sub) -> None:
    p = sub.add_parser("report", help="write a PDF survey report (one visit, a period, or everything)",
                       description="A PDF for the bridge owner: summary with alarm states, layout and target "
                                   "state, displacement histories, every epoch's map, plan and centroids, and a "
                                   "processing log with versions, parameters and file checksums.")
    add_dir(p)
    output_file(p, "--out", required=True, help="the PDF to write", suffixes=(".pdf",))
    g = p.add_mutually_exclusive_group()
    add_epoch(g, required=False, help="report on one visit (with the history up to it): its label")
    g.add_argument("--from", dest="start", metavar="LABEL", help="first epoch of the period")
    p.add_argument("--to", dest="end", metavar="LABEL", help="last epoch of the period")
    p.add_argument("--author", help="who prepared the report (default: your login name)")
    p.set_defaults(func="cmd_report")

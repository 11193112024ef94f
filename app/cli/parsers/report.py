"""The parsers of the ``report`` command: a PDF survey report of one visit, a period or the whole campaign.

They name each command's function in app.cli.commands_report (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import add_dir, add_epoch, output_file


def register(sub) -> None:
    p = sub.add_parser("report", help="write a PDF survey report (one visit, a period, or everything)",
                       description="A PDF for the bridge owner: summary with every target's state and σ, the visits "
                                   "that need attention (a page each), layout, displacement histories, analysis and "
                                   "the field budget, in words. --detail adds the appendix: every visit's map, plan "
                                   "and centroids with flag codes, the field model's tables, and a processing log "
                                   "with versions, parameters, file checksums and the action log.")
    add_dir(p)
    output_file(p, "--out", required=True, help="the PDF to write", suffixes=(".pdf",))
    g = p.add_mutually_exclusive_group()
    add_epoch(g, required=False, help="report on one visit (with the history up to it): its label")
    g.add_argument("--from", dest="start", metavar="LABEL", help="first epoch of the period")
    p.add_argument("--to", dest="end", metavar="LABEL", help="last epoch of the period")
    p.add_argument("--author", help="who prepared the report (default: your login name)")
    p.add_argument("--detail", action="store_true",
                   help="add the appendix: every visit's page, the field model's tables, the processing log")
    p.set_defaults(func="cmd_report")

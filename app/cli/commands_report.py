"""The ``report`` command: a PDF survey report of one visit, a period or the whole campaign."""
from __future__ import annotations

import sys

from app.cli.args import add_dir, add_epoch, output_file
from app.cli.progress import progress_bar


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
    p.set_defaults(func=cmd_report)


def cmd_report(args) -> int:
    from projects.outputs.report import ReportScope, write_report
    from projects.results.table import damaged_line
    from projects.store.campaign import Campaign

    scope = ReportScope(epoch=args.epoch, start=args.start, end=args.end)
    with Campaign.open(args.dir, writable=False) as c:
        with progress_bar("report") as cb:
            path = write_report(c, args.out, scope, author=args.author, progress=cb, detail=args.detail)
        damaged = damaged_line(c)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    if damaged:  # the epoch's page says it too
        print(f"bridgesurvey: warning: {damaged}", file=sys.stderr)
    return 0

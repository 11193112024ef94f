"""The ``report`` command: a PDF survey report of one visit, a period or the whole campaign."""
from __future__ import annotations

from pathlib import Path

from app.cli.progress import progress_bar


def register(sub) -> None:
    p = sub.add_parser("report", help="write a PDF survey report (one visit, a period, or everything)",
                       description="A PDF for the bridge owner: summary with alarm states, layout and target "
                                   "state, displacement histories, every epoch's map, plan and centroids, and a "
                                   "processing log with versions, parameters and file checksums.")
    p.add_argument("dir", type=Path)
    p.add_argument("--out", type=Path, required=True, help="output file (.pdf)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--epoch", help="report on one visit (with the history up to it)")
    g.add_argument("--from", dest="start", help="first epoch of the period")
    p.add_argument("--to", dest="end", help="last epoch of the period")
    p.add_argument("--author", help="who prepared the report (default: your login name)")
    p.set_defaults(func=cmd_report)


def cmd_report(args) -> int:
    from projects.outputs.report import ReportScope, write_report
    from projects.store.campaign import Campaign

    scope = ReportScope(epoch=args.epoch, start=args.start, end=args.end)
    with Campaign.open(args.dir, writable=False) as c:
        with progress_bar("report") as cb:
            path = write_report(c, args.out, scope, author=args.author, progress=cb)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0

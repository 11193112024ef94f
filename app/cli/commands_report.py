"""The ``report`` command: a PDF survey report of one visit, a period or the whole campaign."""
from __future__ import annotations

import sys

from app.cli.progress import progress_bar
from projects.outputs.report import ReportScope, write_report
from projects.results.table import damaged_line
from projects.store.campaign import Campaign


def cmd_report(args) -> int:
    scope = ReportScope(epoch=args.epoch, start=args.start, end=args.end)
    with Campaign.open(args.dir, writable=False) as c:
        with progress_bar("report") as cb:
            path = write_report(c, args.out, scope, author=args.author, progress=cb, detail=args.detail)
        damaged = damaged_line(c)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB)")
    if damaged:  # the epoch's page says it too
        print(f"bridgesurvey: warning: {damaged}", file=sys.stderr)
    return 0

"""Fleet commands: status and report over many campaigns, and processing them on a Dask cluster."""
from __future__ import annotations

import sys
from pathlib import Path

from app.cli.output import dump_json, table
from app.cli.progress import progress_bar
from projects.fleet.process import TlsFiles, fleet_process, scheduler_warning
from projects.fleet.status import fleet_status
from projects.outputs.fleet_report import write_fleet_report


def cmd_fleet_status(args) -> int:
    status = fleet_status(args.roots, overdue_days=args.overdue_days)
    if args.json:
        dump_json(status)
        return 0
    rows = [{"bridge": b["name"], "state": "unreadable" if b["error"] else b["state"], "worst": b["worst_target"],
             "displacement_mm": b["worst_displacement_mm"], "alarm_mm": b["worst_limit_mm"],
             "last_epoch": b["last_epoch"], "days": b["days_since"], "work_left": b["work_left"],
             "problems": b["problems"], "folder": b["folder"] if not b["error"] else f"{b['folder']}: {b['error']}"}
            for b in status["bridges"]]
    table(rows, ["bridge", "state", "worst", "displacement_mm", "alarm_mm", "last_epoch", "days", "work_left",
                 "problems", "folder"])
    ov = status["overview"]
    print(f"{ov['bridges']} bridges: {ov['alarm']} in alarm, {ov['warning']} warning, {ov['ok']} ok, "
          f"{ov['unknown']} unknown, {ov['unreadable']} unreadable; {ov['work_left']} epoch(s) with work left"
          + (f"; overdue (> {ov['overdue_days']} days): {', '.join(ov['overdue'])}" if ov["overdue"] else ""))
    return 0


def cmd_fleet_report(args) -> int:
    status = fleet_status(args.roots, overdue_days=args.overdue_days)
    path = write_fleet_report(status, args.out)
    print(f"wrote {path}: {status['overview']['bridges']} bridges")
    return 0


def cmd_fleet_process(args) -> int:
    given = (args.tls_ca_file, args.tls_cert, args.tls_key)
    tls = TlsFiles(*given) if any(given) else None
    if args.scheduler and (warning := scheduler_warning(args.scheduler)):
        print(f"bridgesurvey: warning: {warning}", file=sys.stderr)
    with progress_bar("fleet") as cb:
        run = fleet_process(args.roots, scheduler=args.scheduler, workers=args.workers, tls=tls, progress=cb)
    if args.json:
        dump_json(run.to_json())
    else:
        rows = []
        for cr in run.campaigns:
            acts = [o.action for o in cr.summary.outcomes]
            rows.append({"campaign": cr.name or Path(cr.folder).name, "epochs": cr.tasks,
                         "measured": acts.count("measured"), "planned": acts.count("planned"),
                         "failed": acts.count("failed"), "skipped": cr.skipped or "-",
                         "problems": len(cr.summary.problems)})
        table(rows, ["campaign", "epochs", "measured", "planned", "failed", "problems", "skipped"])
        print(f"{run.tasks} epoch task(s) on {run.cluster or 'no cluster (nothing to do)'}; {run.failed} failed")
        for note in run.notes:
            print(f"warning: {note}")
    return 0 if not run.failed and not any(cr.skipped for cr in run.campaigns) else 3

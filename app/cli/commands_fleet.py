"""Fleet commands: status and report over many campaigns, and processing them on a Dask cluster."""
from __future__ import annotations

import sys
from pathlib import Path

from app.cli.args import add_json, output_file
from app.cli.output import dump_json, table

ROOT_HELP = "a folder holding campaigns, a campaign folder (DIR), or a fleet file listing such folders"
from app.cli.progress import progress_bar


def register(sub) -> None:
    p = sub.add_parser("fleet", help="many bridges: status, summary report, processing on a Dask cluster",
                       description="ROOT is a folder holding campaigns (searched recursively), a campaign folder, "
                                   "or a fleet file listing such folders, one per line.")
    fs = p.add_subparsers(dest="fleet_command", metavar="ACTION")
    fs.required = True
    q = fs.add_parser("status", help="every bridge: last epoch, work left, worst alarm state")
    q.add_argument("roots", type=Path, nargs="+", metavar="ROOT", help=ROOT_HELP)
    q.add_argument("--overdue-days", type=int, default=10, help="a bridge not visited for longer is overdue (10)")
    add_json(q)
    q.set_defaults(func=cmd_fleet_status)
    q = fs.add_parser("report", help="fleet summary PDF: an overview and one line per bridge")
    q.add_argument("roots", type=Path, nargs="+", metavar="ROOT", help=ROOT_HELP)
    output_file(q, "--out", required=True, help="the PDF to write", suffixes=(".pdf",))
    q.add_argument("--overdue-days", type=int, default=10, help="a bridge not visited for longer is overdue (10)")
    q.set_defaults(func=cmd_fleet_report)
    q = fs.add_parser("process", help="bring every campaign up to date on a Dask cluster",
                      description="Runs each stale epoch's stage 1 (plan and centroids from its scans) as a "
                                  "dask.distributed task, saves results into each campaign as they arrive, then "
                                  "computes the displacements. Default: a LocalCluster of worker processes here; "
                                  "--scheduler uses a running cluster whose workers have BridgeSurvey installed "
                                  "and see the campaign folders at the same paths. A campaign another process is "
                                  "writing is skipped. Ctrl-C stops cleanly (what is saved stays).")
    q.add_argument("roots", type=Path, nargs="+", metavar="ROOT", help=ROOT_HELP)
    q.add_argument("--scheduler", default=None,
                   help="address of a running Dask scheduler: tls://host:8786 on a network (with the certificates), "
                        "tcp://127.0.0.1:8786 on this machine")
    q.add_argument("--tls-ca-file", default=None, metavar="PEM",
                   help="the certificate authority of a tls:// scheduler's cluster (default: Dask's configuration)")
    q.add_argument("--tls-cert", default=None, metavar="PEM", help="this client's certificate for a tls:// scheduler")
    q.add_argument("--tls-key", default=None, metavar="PEM", help="this client's private key for a tls:// scheduler")
    q.add_argument("--workers", type=int, default=None, help="worker processes of the local cluster (default: cores)")
    add_json(q, help="print what was done as JSON")
    q.set_defaults(func=cmd_fleet_process)


def cmd_fleet_status(args) -> int:
    from projects.fleet.status import fleet_status

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
    from projects.fleet.status import fleet_status
    from projects.outputs.fleet_report import write_fleet_report

    status = fleet_status(args.roots, overdue_days=args.overdue_days)
    path = write_fleet_report(status, args.out)
    print(f"wrote {path}: {status['overview']['bridges']} bridges")
    return 0


def cmd_fleet_process(args) -> int:
    from projects.fleet.process import TlsFiles, fleet_process, scheduler_warning

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

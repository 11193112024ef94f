"""The parsers of fleet commands: status and report over many campaigns, and processing them on a Dask cluster.

They name each command's function in app.cli.commands_fleet (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from pathlib import Path

from app.cli.args import add_json, output_file

ROOT_HELP = "a folder holding campaigns, a campaign folder (DIR), or a fleet file listing such folders"


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
    q.set_defaults(func="cmd_fleet_status")
    q = fs.add_parser("report", help="fleet summary PDF: an overview and one line per bridge")
    q.add_argument("roots", type=Path, nargs="+", metavar="ROOT", help=ROOT_HELP)
    output_file(q, "--out", required=True, help="the PDF to write", suffixes=(".pdf",))
    q.add_argument("--overdue-days", type=int, default=10, help="a bridge not visited for longer is overdue (10)")
    q.set_defaults(func="cmd_fleet_report")
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
    q.set_defaults(func="cmd_fleet_process")

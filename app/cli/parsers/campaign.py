"""The parsers of campaign commands: init, add-epoch, add-fine, plan, process, displacements, status, reflector, limit, export, demo.

They name each command's function in app.cli.commands_campaign (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from pathlib import Path

from app.cli.args import (
    RawDescriptionHelpFormatter,
    add_dir,
    add_epoch,
    add_json,
    input_file,
    output_file,
    output_folder,
)
from projects.processing.parameters import help_text

#: Epochs 'status' lists without --all.
STATUS_EPOCHS = 12


def register(sub) -> None:
    p = sub.add_parser("init", help="create a campaign for one bridge",
                       description="Create a campaign folder with its reflector layout.")
    add_dir(p)
    p.add_argument("--name", required=True, help="structure / campaign name")
    input_file(p, "--layout", required=True, help="layout.csv: id,group,x,y,z[,diameter_mm][,nx,ny,nz]")
    p.add_argument("--target-diameter-mm", type=float, default=50.0, help="diameter when the layout has none (50)")
    p.add_argument("--span-m", type=float, default=None, help="span length, for span-fraction limits")
    p.add_argument("--scanner", default=None,
                   help="scanner profile: a name from 'bridgesurvey scanners' or a profile .json (default Riegl VZ-1000)")
    p.add_argument("--timezone", default="UTC", metavar="ZONE",
                   help="the bridge's time zone: imported times without an offset are read in it (IANA name such as "
                        "Europe/Berlin, or +hh:mm; default UTC; 'settings DIR timezone ZONE' changes it)")
    p.set_defaults(func="cmd_init")

    p = sub.add_parser("add-epoch", help="import a visit: its coarse scan (and fine scans, if any)",
                       description="Import the scans of one visit. Files are checked, copied into the campaign "
                                   "once and never modified.")
    add_dir(p)
    p.add_argument("--date", required=True, help="ISO 8601 date or date-time of the visit (UTC unless it says)")
    input_file(p, "--coarse", required=True, help="the visit's coarse scan (LAS, LAZ, E57, PLY, PCD, PTX, PTS, XYZ)")
    input_file(p, "--fine", nargs="*", default=[], help="its fine scans, when already made (or later: add-fine)")
    p.add_argument("--label", default=None, help="epoch label (default: the date)")
    p.add_argument("--notes", default="", help="station notes")
    p.add_argument("--scanner", default=None, help="this visit's scanner when it is not the campaign's "
                                                   "(a name from 'bridgesurvey scanners' or a profile .json)")
    p.add_argument("--allow-date", action="store_true",
                   help="accept a date more than 3 years from the campaign's other epochs (it is refused otherwise)")
    add_pose_options(p)
    p.set_defaults(func="cmd_add_epoch")

    p = sub.add_parser("add-setup", help="import another set-up (station) of a visit: its coarse and fine scans",
                       description="A visit may need several stations (a long bridge, a pier hiding targets). Each "
                                   "set-up is measured in its own scanner frame, then the set-ups are joined through "
                                   "the targets they share (at least three, well spread).")
    add_dir(p)
    p.add_argument("--epoch", required=True, help="the visit (epoch label) the set-up belongs to")
    input_file(p, "--coarse", required=True, help="the set-up's coarse scan")
    input_file(p, "--fine", nargs="*", default=[], help="its fine scans, if any yet")
    p.add_argument("--scanner", default=None, help="this set-up's scanner when it is not the visit's "
                                                   "(a name from 'bridgesurvey scanners' or a profile .json)")
    add_pose_options(p)
    p.set_defaults(func="cmd_add_setup")

    p = sub.add_parser("add-fine", help="import the fine scans of an epoch",
                       description="Import the fine scans of an epoch (made from its plan). Files are checked, "
                                   "copied into the campaign once and never modified.")
    add_dir(p)
    add_epoch(p)
    input_file(p, "files", nargs="+", metavar="FILE", help="fine scan file(s); one file may hold many windows")
    add_setup_option(p)
    add_pose_options(p)
    p.set_defaults(func="cmd_add_fine")

    p = sub.add_parser("plan", help="plan the fine scans of an epoch from its coarse scan",
                       description="Find and identify the targets in the epoch's coarse scan and plan a fine-scan "
                                   "window for each: angles, steps, expected points and seconds, and the total "
                                   "against the visit's time budget. Writes the plan JSON (and, with --sheet, the "
                                   "printable field sheet).")
    add_dir(p)
    add_epoch(p)
    add_setup_option(p)
    output_file(p, "--out", required=True, help="plan JSON to write")
    output_file(p, "--sheet", default=None, help="also write the printable field sheet (PDF)", suffixes=(".pdf",))
    p.add_argument("--no-closure", action="store_true",
                   help="leave out the closure window (the first reference target again at the end, which measures "
                        "the set-up's drift during the visit); the campaign keeps its plan")
    p.set_defaults(func="cmd_plan")

    p = sub.add_parser("process", help="bring epochs up to date: plans, centroids, displacements",
                       description="Process new or changed epochs only; up-to-date ones are not recomputed. Prints "
                                   "one line per epoch computed and a summary. Exit 3 when an epoch has no "
                                   "trustworthy result (a problem flag).")
    add_dir(p)
    add_epoch(p, required=False, action="append", default=None,
              help="only this epoch (repeatable; default: every epoch)")
    add_json(p, help="print what was done as JSON (every epoch, with its action and state)")
    p.add_argument("--accept-check", action="store_true",
                   help="process an epoch whose on-site check asked for a re-scan as it is (the choice is logged); "
                        "without it such an epoch is refused until its re-scan is added")
    p.set_defaults(func="cmd_process")

    p = sub.add_parser("displacements", help="print or write the displacement history",
                       description="One row per processed epoch and measurement target: displacement (mm, "
                                   "positive up, against the baseline), sigma, flags, limit state and the "
                                   "epoch's state (epoch_state), as CSV or JSON.")
    add_dir(p)
    p.add_argument("--format", choices=("csv", "json"), default="csv", help="csv (default) or json")
    output_file(p, "--out", default=None, help="write to this file instead of the terminal")
    p.set_defaults(func="cmd_displacements")

    p = sub.add_parser("status", help="epochs, what is stale, and the alarm state of every target",
                       description="The campaign at a glance: the latest epochs with their state (imported, "
                                   "planned, scanned, measured, processed, warning, problem) and flags, which "
                                   "epochs have warnings or problems, and the latest displacement of every "
                                   "measurement target against its limits.")
    add_dir(p)
    p.add_argument("--all", action="store_true", help=f"list every epoch (default: the last {STATUS_EPOCHS})")
    p.add_argument("--verbose", action="store_true", help="every flag of every epoch in full (default: one line a "
                   "visit, the flags in words and counts, the action below it when one is needed)")
    add_json(p, help="print the whole status as JSON (every epoch)")
    p.set_defaults(func="cmd_status")

    p = sub.add_parser("reflector", help="list, add, retire or replace reflectors",
                       description="The campaign's reflector targets: list them, add one, retire one, or replace "
                                   "one by another whose history continues the old one's "
                                   "(bridgesurvey reflector ACTION DIR ...).")
    rs = p.add_subparsers(dest="action", metavar="ACTION")
    rs.required = True
    q = rs.add_parser("list", help="every reflector with its group, position and life")
    add_dir(q)
    add_json(q)
    q = rs.add_parser("add", help="a new reflector (from a date on)")
    add_dir(q)
    q.add_argument("id", help="the new reflector's id")
    q.add_argument("--group", required=True, choices=("reference", "measurement"),
                   help="reference (on a pier) or measurement (under the deck)")
    q.add_argument("--xyz", required=True, help="approximate x,y,z in the layout's frame (m)")
    q.add_argument("--diameter-mm", type=float, default=50.0, help="target diameter (50)")
    q.add_argument("--installed", default=None, help="ISO date from which scans should hold it")
    q = rs.add_parser("retire", help="a reflector that is gone (kept in the history)")
    add_dir(q)
    q.add_argument("id", help="the reflector's id")
    q.add_argument("--date", required=True, help="ISO date from which it is gone")
    q = rs.add_parser("replace", help="a new reflector continuing an old one's history")
    add_dir(q)
    q.add_argument("old", help="the id of the reflector replaced")
    q.add_argument("new", help="the id of its replacement")
    q.add_argument("--date", required=True, help="ISO date of the replacement")
    q.add_argument("--xyz", default=None, help="new position if not the same place")
    for q in rs.choices.values():
        q.set_defaults(func="cmd_reflector")

    p = sub.add_parser("limit", help="set warning/alarm limits",
                       description="Rules: abs:WARN_MM,ALARM_MM | span:NW,NA (L/NW, L/NA) | kr-rail:0-200|200-270|270-350"
                                   " | prediction:TOL_MM (flag a departure from the design prediction)")
    add_dir(p)
    p.add_argument("--rule", required=True, help="the rule (see above)")
    p.add_argument("--reflector", default="*", help="one target (default: every measurement target)")
    p.set_defaults(func="cmd_limit")

    p = sub.add_parser("settings", help="show or change processing parameters (marks what becomes stale)",
                       formatter_class=RawDescriptionHelpFormatter,
                       description="Without KEY: list the parameters. With KEY VALUE: change one; 'process' then "
                                   "recomputes exactly the results it affects\n(stale: plan = plans and centroids "
                                   "of every epoch, displacements = displacements only, baseline = every "
                                   "displacement).\n\n" + help_text() + "\n  scanner (NAME | FILE.json): the "
                                   "campaign's instrument (with --epoch: one visit's)\n  timezone (an IANA name "
                                   "such as "
                                   "Europe/Berlin, or +hh:mm; default UTC): the zone imported times without an "
                                   "offset are read in")
    add_dir(p)
    p.add_argument("key", nargs="?", help="the parameter to change (see above; none: list them all)")
    p.add_argument("value", nargs="?", help="its new value (none: back to the default)")
    add_epoch(p, required=False, help="with 'scanner': set the scanner of this epoch only")
    p.set_defaults(func="cmd_settings")

    p = sub.add_parser("export", help="export tables: .xlsx (everything) or .csv (displacements)")
    add_dir(p)
    output_file(p, "--out", required=True, help="the file to write: .xlsx (every table) or .csv (displacements)",
                suffixes=(".xlsx", ".csv"))
    p.set_defaults(func="cmd_export")

    p = sub.add_parser("demo", help="build and process a simulated one-year demo campaign",
                       description="Simulate a year of weekly visits of a 40 m bridge (scanner somewhere new each "
                                   "week, dead-load steps, creep, seasonal swings, a cable tie, an occluded target), "
                                   "import and process them like real data. The last visit is the Monday before "
                                   "today. Run it again to resume.")
    output_folder(p, "dir", metavar="DIR", help="the folder for the demo campaign (created; resumed when it holds one)")
    p.add_argument("--weeks", type=int, default=52, help="weekly visits to simulate (52)")
    p.add_argument("--seed", type=int, default=2026, help="random seed of the simulation (2026)")
    p.set_defaults(func="cmd_demo")


def add_setup_option(p) -> None:
    """``--setup K``: which set-up of the visit (1-based; default the last one added)."""
    p.add_argument("--setup", type=int, default=None, metavar="K",
                   help="the set-up of the visit (1, 2...; default: the last one added)")


def add_pose_options(p) -> None:
    """``--pose``, ``--origin``, ``--up``: the scanner pose of scans exported in a project frame."""
    p.add_argument("--pose", type=Path, default=None, metavar="FILE",
                   help="the scanner pose of scans exported in a project frame: a 4x4 matrix, scanner frame to "
                        "project frame, rows of four numbers, '#' comments (RiSCAN's SOP export, a Cyclone "
                        "transformation text)")
    p.add_argument("--origin", default=None, metavar="X,Y,Z",
                   help="the scanner's position in the project frame, when only that is known (instead of --pose)")
    p.add_argument("--up", default=None, metavar="UX,UY,UZ",
                   help="with --origin: the scanner's vertical in the project frame (default 0,0,1)")

"""The parsers of camera commands: import a dual-camera displacement series, list them, cross-validate with LiDAR.

They name each command's function in app.cli.commands_camera (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import add_dir, add_json, input_file, output_folder


def register(sub) -> None:
    p = sub.add_parser("camera", help="import or list displacement series of a dual-camera installation",
                       description="Displacement series written by an existing dual-camera system (CSV/TXT with "
                                   "a time column and a displacement column).")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    q = actions.add_parser("import", help="import a series file (copied into the campaign, never modified)",
                           description="Columns are recognised by their names: time/timestamp/datetime (or "
                                       "date + time, or unix seconds), displacement/disp/deflection/value (unit in "
                                       "the name, e.g. displacement_mm), optional unit and tz columns. Bad rows are "
                                       "left out and reported with their line numbers.")
    add_dir(q)
    input_file(q, "file", help="the series file (CSV or TXT)")
    q.add_argument("--name", default=None, help="series name (default: the file name)")
    q.add_argument("--reflector", default=None, help="LiDAR target the camera watches (default: the one at midspan)")
    q.add_argument("--column", default=None, help="value column, when the file has several")
    q.add_argument("--timezone", default=None, metavar="ZONE",
                   help="the zone of times without an offset (IANA name or +hh:mm; default: the campaign's, "
                        "see 'status')")
    q.add_argument("--unit", default=None, help="unit of the values when the file does not say (default mm)")
    q.add_argument("--positive", choices=("up", "down"), default="up", help="the file's sign convention (up)")
    add_json(q, help="print the import summary as JSON")
    q.set_defaults(func="cmd_camera_import")
    q = actions.add_parser("list", help="list the imported series")
    add_dir(q)
    add_json(q)
    q.set_defaults(func="cmd_camera_list")

    p = sub.add_parser("crossval", help="cross-validate a camera series against the LiDAR epochs",
                       description="Pair each LiDAR epoch with the camera samples around its time, align the "
                                   "camera's zero (at a date, or by least squares), and report bias, RMSE and "
                                   "correlation. Writes crossval.json, crossval.csv, overlay.png, difference.png "
                                   "and scatter.png.")
    add_dir(p)
    output_folder(p, "--out", required=True, help="output folder (created when missing)")
    p.add_argument("--align-at", default=None, help="align both series at the epoch nearest this date")
    p.add_argument("--series", default=None, help="camera series (when there are several)")
    p.add_argument("--reflector", default=None, help="LiDAR target (default: the series' own)")
    p.add_argument("--window-min", type=float, default=30.0, help="pairing window, +- minutes (30)")
    add_json(p, help="print the summary as JSON")
    p.set_defaults(func="cmd_crossval")

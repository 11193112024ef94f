"""The parsers of field commands: field-sheet, check (before leaving the site), stations.

They name each command's function in app.cli.commands_field (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import add_dir, add_epoch, add_json, input_file, output_file
from app.cli.parsers.campaign import add_setup_option


def register(sub) -> None:
    p = sub.add_parser("field-sheet", help="printable PDF of an epoch's plan in the instrument's own terms",
                       description="Each window with a map thumbnail, the angles and resolution to enter on the "
                                   "instrument, expected points and seconds, and the total against the budget.")
    add_dir(p)
    add_epoch(p)
    output_file(p, "--out", required=True, help="PDF to write", suffixes=(".pdf",))
    add_setup_option(p)
    p.set_defaults(func="cmd_field_sheet")

    p = sub.add_parser("check", help="before leaving the site: is every target found, with enough points?",
                       description="Measures the epoch's fine scans and reports per target: found, points against "
                                   "the plan, vertical centroid sigma against the goal (what the plan promised, "
                                   "+30 %). Writes a re-scan plan (plan JSON) for the targets that fall short. "
                                   "Exit 0 when all are good, 3 when some fall short. The centroids are kept: "
                                   "'process' then computes the displacements without measuring again.")
    add_dir(p)
    add_epoch(p)
    output_file(p, "--out", default=None, help="re-scan plan JSON to write (when a target falls short)")
    p.add_argument("--goal-mm", type=float, default=None, help="vertical centroid sigma goal (default: the plan's)")
    add_json(p, help="print every target's check as JSON")
    add_setup_option(p)
    p.set_defaults(func="cmd_check")

    p = sub.add_parser("stations", help="where to stand: predicted sigma of every target from candidate positions",
                       description="Evaluates scanner positions on a grid inside the allowed area and predicts, "
                                   "for each, the sigma of every target's vertical displacement (range, incidence, "
                                   "footprint and the points the plan would get), hidden targets and scan time.")
    add_dir(p)
    output_file(p, "--out", required=True, help="stations JSON to write (best first)")
    input_file(p, "--area", default=None, help="area.csv: x,y polygon vertices in the layout frame "
                                               "(default: a 25 m band on both sides of the bridge)")
    p.add_argument("--height-m", type=float, default=1.5, help="instrument height above the ground (1.5 m)")
    p.add_argument("--grid-m", type=float, default=2.0, help="grid spacing (2 m)")
    p.add_argument("--ground-z", type=float, default=None,
                   help="ground height in the layout frame (default: from the last measured station)")
    output_file(p, "--png", default=None, help="also draw the station map (PNG)")
    p.add_argument("--top", type=int, default=5, help="stations to print (5)")
    p.add_argument("--sigma-mm", type=float, default=None,
                   help="the sigma asked of every deck target's displacement, mm: the best single station's targets "
                        "above it are named, and the second station that measures them is proposed")
    p.add_argument("--pair", action="store_true",
                   help="also propose two set-ups for one visit: the best station and the second that most improves "
                        "the worst target (proposed anyway when the best station hides a deck target)")
    p.add_argument("--first", default=None, metavar="X,Y",
                   help="where set-up 1 will stand (layout frame, metres; e.g. one end of a long bridge, where the "
                        "access is): it is evaluated, what it cannot measure is named, and the second station "
                        "that completes it is proposed, with the visit planned together from the two positions")
    p.set_defaults(func="cmd_stations")

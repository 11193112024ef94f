"""The parsers of commands working on single scan files, outside any campaign: detect, plan-file, centroids, simulate.

They name each command's function in app.cli.commands_files (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from pathlib import Path

from app.cli.args import add_json, input_file, output_file, output_folder


def register(sub) -> None:
    p = sub.add_parser("detect", help="find and identify the reflectors in a coarse scan file",
                       description="Build the reflectance map of a coarse scan, detect bright target-sized "
                                   "blobs and identify them against the layout.")
    input_file(p, "scan", help="coarse scan (LAS, LAZ, E57, PLY, PCD, PTX, XYZ)")
    input_file(p, "--layout", required=True, help="layout.csv: id,group,x,y,z[,diameter_mm]")
    p.add_argument("--diameter-mm", type=float, default=None, help="target diameter when the layout has none (50)")
    p.add_argument("--step-deg", type=float, default=None, help="reflectance-map cell size (default: from the scan)")
    p.add_argument("--threshold", type=float, default=None, help="intensity threshold in [0,1] (default: automatic)")
    output_file(p, "--png", default=None, help="also save the reflectance map with the detections")
    add_json(p)
    p.set_defaults(func="cmd_detect")

    p = sub.add_parser("plan-file", help="plan the fine scans from a coarse scan file",
                       description="Detect and identify the reflectors of a coarse scan and write the fine-scan "
                                   "plan (plan JSON).")
    p.add_argument("scan", type=Path, help="coarse scan (LAS, LAZ, E57, PLY, PCD, PTX, XYZ)")
    p.add_argument("--layout", type=Path, required=True, help="layout.csv: id,group,x,y,z[,diameter_mm]")
    p.add_argument("--out", type=Path, required=True, help="plan JSON to write")
    p.add_argument("--epoch", default="", help="epoch label stored in the plan")
    p.add_argument("--min-points", type=int, default=1000, help="points each target should receive (1000)")
    p.add_argument("--budget-min", type=float, default=60.0, help="time available for the fine scans (60 min)")
    p.add_argument("--diameter-mm", type=float, default=None, help="target diameter when the layout has none (50)")
    p.add_argument("--png", type=Path, default=None, help="also save the map with the planned windows")
    p.add_argument("--scanner", default="Riegl VZ-1000",
                   help="scanner profile: a name from 'bridgesurvey scanners' or a profile .json (Riegl VZ-1000)")
    p.add_argument("--json", action="store_true", help="print the plan JSON instead of a table")
    p.set_defaults(func="cmd_plan_file")

    p = sub.add_parser("centroids", help="measure the target centroids in fine scan files",
                       description="Cut the fine scans into the plan's windows and measure each target's "
                                   "centroid with its covariance and flags.")
    input_file(p, "scans", nargs="+", metavar="SCAN", help="fine scan file(s) of one set-up")
    input_file(p, "--plan", required=True, help="the plan JSON the fine scans were made from")
    input_file(p, "--layout", default=None, help="for the target diameters (default 50 mm)")
    add_json(p)
    p.set_defaults(func="cmd_centroids")

    p = sub.add_parser("simulate", help="simulate a scanner visit of a bridge (files + ground truth)",
                       description="Write a simulated coarse scan of a 40 m bridge with 9 targets (or, with "
                                   "--fine, the fine scans of a plan) into a folder, with the layout and truth.")
    output_folder(p, "folder", metavar="FOLDER", help="folder to write the scan, layout.csv and truth.json into")
    input_file(p, "--fine", default=None, metavar="PLAN", help="scan the windows of this plan")
    p.add_argument("--seed", type=int, default=1, help="random seed (1)")
    p.add_argument("--position", default="20,-12,1.5", help="scanner x,y,z in the bridge frame (m)")
    p.add_argument("--heading-deg", type=float, default=30.0, help="scanner heading (30 deg)")
    p.add_argument("--midspan-mm", type=float, default=0.0, help="midspan displacement, positive up")
    p.add_argument("--cable-tie", action="append", default=[], metavar="ID", help="a cable tie beside this target "
                                                                                   "(repeatable)")
    p.add_argument("--occlude", action="append", default=[], metavar="ID", help="hide this target (repeatable)")
    p.add_argument("--move", action="append", default=[], metavar="ID:DX,DY,DZ", help="move a target (metres)")
    p.add_argument("--coarse-step-deg", type=float, default=0.04, help="angular step of the coarse scan (0.04)")
    p.set_defaults(func="cmd_simulate")

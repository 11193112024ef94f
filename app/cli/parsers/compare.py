"""The parsers of the ``compare`` command: whole-scan comparison of two epochs (registration, change, span profile).

They name each command's function in app.cli.commands_compare (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("compare", help="compare the whole scans of two epochs (registration, C2C/M3C2, span profile)",
                       description="Register both epochs into the campaign frame (reference targets as tie points, "
                                   "then ICP on the piers and the ground around them), compute cloud-to-cloud or "
                                   "M3C2 change and a span profile next to the target displacements. Writes "
                                   "change.laz, summary.json, registration.csv, span_profile.csv and .png.")
    p.add_argument("dir", type=Path)
    p.add_argument("--from", dest="start", required=True, help="first epoch")
    p.add_argument("--to", dest="end", required=True, help="second epoch")
    p.add_argument("--method", choices=("c2c", "m3c2"), default="m3c2", help="change computation: c2c or m3c2 (m3c2)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--registration", choices=("icp", "ndt", "targets"), default=None,
                   help="refine the target registration on the stable parts with point-to-plane ICP (default), PCL's NDT "
                        "(pcl_ndt3d, Debian pcl-tools) or not at all (targets)")
    p.add_argument("--no-icp", action="store_true", help="register on the targets only (= --registration targets)")
    p.add_argument("--bin-m", type=float, default=2.5, help="span profile bin length (default 2.5 m)")
    m = p.add_argument_group("change parameters (py4dgeo's names, metres)")
    m.add_argument("--normal-radii", type=float, nargs="+", default=[0.5], metavar="R",
                   help="M3C2 normal radii; several make the normals multi-scale (default 0.5)")
    m.add_argument("--cyl-radius", type=float, default=0.25, metavar="R",
                   help="M3C2 projection cylinder radius (default 0.25)")
    m.add_argument("--max-distance", type=float, default=None, metavar="D",
                   help="M3C2 cylinder half-length (default 0.5); C2C search distance (default 1.0)")
    m.add_argument("--corepoints", default="0.25", metavar="STEP|FILE",
                   help="M3C2 core points: a grid step over the first epoch (default 0.25) or a point file in "
                        "the campaign frame (any scan format)")
    m.add_argument("--registration-error", default="measured", metavar="E|measured",
                   help="added to M3C2's level of detection: metres, or 'measured' (default: the two target "
                        "registrations' RMS combined)")
    m.add_argument("--robust-aggr", action="store_true",
                   help="M3C2 median and inter-quartile spread instead of mean and standard deviation")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func="cmd_compare")

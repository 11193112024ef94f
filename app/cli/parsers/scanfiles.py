"""The parsers of commands on scan files themselves: ``info`` (what a file holds) and ``convert`` (between formats).

They name each command's function in app.cli.commands_scanfiles (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("info", help="describe scan files (format, scans, poses, points, intensity, step, problems)",
                       description="Describe scan files at header speed, with the same checks as every other "
                                   "command: format and version, scans and their poses, point counts, bounds, "
                                   "scales and point format from the header, and the angular steps in both angles "
                                   "from a few runs of consecutive points. --stats reads every point in chunks "
                                   "(memory bounded whatever the file's size) for the bounds, ranges, intensity "
                                   "range and vendor convention, duplicates, the steps from whole angular patches "
                                   "of the scan, and the problems found. PTX, PTS and XYZ files are always read "
                                   "whole.")
    p.add_argument("files", type=Path, nargs="+", help="LAS, LAZ, E57, PLY, PCD, PTX, PTS or XYZ files")
    p.add_argument("--stats", "--full", dest="stats", action="store_true",
                   help="read every point (in chunks) for ranges, intensity, duplicates and the angular steps")
    p.add_argument("--json", action="store_true", help="print JSON (a list, one entry per file)")
    p.set_defaults(func="cmd_info")

    p = sub.add_parser("convert", help="convert a scan file to another format (pose and intensity kept)",
                       description="Convert between the supported formats by suffix. The scanner pose and the "
                                   "raw intensity are kept (LAS/LAZ store intensity as 16-bit: other ranges "
                                   "are rescaled); LAS/LAZ to LAS/LAZ copies every point record as it is. Files "
                                   "with several scans convert to E57, or one scan at a time with --scan. LAS, "
                                   "LAZ, E57, binary PLY and binary PCD inputs are read in chunks and written in "
                                   "chunks to LAS, LAZ, PLY, PCD, XYZ and PTS, in memory bounded whatever the "
                                   "file's size.")
    p.add_argument("input", type=Path, help="the scan file to convert (LAS, LAZ, E57, PLY, PCD, PTX, PTS or XYZ)")
    p.add_argument("output", type=Path, help="suffix: .las .laz .e57 .ply .pcd .ptx .pts .xyz .txt")
    p.add_argument("--scan", type=int, default=None, metavar="K", help="only scan K (0-based) of a multi-scan file")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func="cmd_convert")

"""Commands on scan files themselves: ``info`` (what a file holds) and ``convert`` (between formats)."""
from __future__ import annotations

from pathlib import Path

from app.cli.output import dump_json
from common.errors import InputError


def register(sub) -> None:
    p = sub.add_parser("info", help="describe scan files (format, scans, poses, points, intensity, step, problems)",
                       description="Read scan files with the same checks as every other command and describe "
                                   "them: format and version, scans and their poses, point count, bounds, the "
                                   "intensity range and vendor convention, the angular step estimated from the "
                                   "points (and the point spacing at 10 m), and the problems found.")
    p.add_argument("files", type=Path, nargs="+", help="LAS, LAZ, E57, PLY, PCD, PTX, PTS or XYZ files")
    p.add_argument("--json", action="store_true", help="print JSON (a list, one entry per file)")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("convert", help="convert a scan file to another format (pose and intensity kept)",
                       description="Convert between the supported formats by suffix. The scanner pose and the "
                                   "raw intensity are kept (LAS/LAZ store intensity as 16-bit: other ranges "
                                   "are rescaled). Files with several scans convert to E57, or one scan at a "
                                   "time with --scan.")
    p.add_argument("input", type=Path)
    p.add_argument("output", type=Path, help="suffix: .las .laz .e57 .ply .pcd .ptx .pts .xyz .txt")
    p.add_argument("--scan", type=int, default=None, metavar="K", help="only scan K (0-based) of a multi-scan file")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")
    p.set_defaults(func=cmd_convert)


#: Formats that cannot hold a scanner pose (others carry it in their header).
NO_POSE = (".pts",)


def _fmt_xyz(v) -> str:
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def cmd_info(args) -> int:
    from lidar.io.info import describe_file

    infos = [describe_file(f) for f in args.files]
    if args.json:
        dump_json([i.to_dict() for i in infos])
        return 0
    for info in infos:
        version = f" {info.version}" if info.version else ""
        print(f"{info.path}: {info.format}{version}, {info.size_bytes:,} bytes, {len(info.scans)} scan(s)")
        for k, d in sorted(info.details.items()):
            print(f"  {k}: {d}")
        for s in info.scans:
            print(f"  scan '{s.name}': {s.points:,} points")
            print(f"    bounds ({'project frame' if s.frame == 'project' else 'SOCS'}, m): {_fmt_xyz(s.bounds_min)} .. "
                  f"{_fmt_xyz(s.bounds_max)}; "
                  f"range {s.range_m[0]:.2f}-{s.range_m[1]:.2f} m")
            if s.pose is not None:
                t = [row[3] for row in s.pose[:3]]
                print(f"    pose: translation {_fmt_xyz(t)} (4x4 with --json)")
            else:
                print("    pose: none (points are in " + ("a project frame)" if s.frame == "project" else
                                                   "the scanner's frame)"))
            if s.intensity_raw_range is not None:
                lo, hi = s.intensity_raw_range
                print(f"    intensity: raw {lo:g}..{hi:g}, convention: {s.intensity_convention}")
            else:
                print("    intensity: none")
            if s.angular_step_deg is not None:
                print(f"    angular step: {s.angular_step_deg:.4f} deg (point spacing {s.spacing_at_10m_mm:.1f} mm "
                      f"at 10 m)")
            for problem in s.problems:
                print(f"    problem: {problem}")
    return 0


def cmd_convert(args) -> int:
    from lidar.io import WRITE_SUFFIXES, read_scans, write_scan
    from lidar.io.e57 import write_e57

    suffix = args.output.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise InputError(f"{args.output}: cannot write '{suffix or '(no suffix)'}'; use one of "
                         f"{', '.join(WRITE_SUFFIXES)}")
    if args.output.exists() and not args.force:
        raise InputError(f"{args.output}: already exists; choose another name or add --force")
    if args.output.resolve() == args.input.resolve():
        raise InputError(f"{args.output}: is the input file; write the conversion to a new file")
    scans = read_scans(args.input)
    if args.scan is not None:
        if not 0 <= args.scan < len(scans):
            raise InputError(f"{args.input}: holds {len(scans)} scan(s); --scan must be 0-{len(scans) - 1}")
        scans = [scans[args.scan]]
    if len(scans) > 1 and suffix != ".e57":
        raise InputError(f"{args.input}: holds {len(scans)} scans; convert to .e57 to keep them all, or pick one "
                         "with --scan K")
    if suffix == ".e57":
        write_e57(scans, args.output)
    else:
        write_scan(scans[0], args.output)
    n = sum(len(s) for s in scans)
    if scans[0].pose is None:
        kept = "intensity kept (the input has no pose)"
    elif suffix in NO_POSE:
        kept = f"intensity kept; the pose is not: {suffix[1:].upper()} has no place for it"
    else:
        kept = "pose and intensity kept"
    print(f"{args.output}: {n:,} points from {args.input} ({kept})")
    return 0

"""Commands on scan files themselves: ``info`` (what a file holds) and ``convert`` (between formats)."""
from __future__ import annotations

from app.cli.output import dump_json
from common.errors import InputError
from lidar.io import WRITE_SUFFIXES
from lidar.io.convert import convert_file
from lidar.io.info import describe_file


def _fmt_xyz(v) -> str:
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def cmd_info(args) -> int:
    infos = [describe_file(f, stats=args.stats) for f in args.files]
    if args.json:
        dump_json([i.to_dict() for i in infos])
        return 0
    for info in infos:
        version = f" {info.version}" if info.version else ""
        how = "every point read" if info.stats else "from the header; --stats reads every point"
        print(f"{info.path}: {info.format}{version}, {info.size_bytes:,} bytes, {len(info.scans)} scan(s) ({how})")
        for k, d in sorted(info.details.items()):
            print(f"  {k}: {d}")
        for s in info.scans:
            _print_scan(s)
    return 0


def _print_scan(s) -> None:
    print(f"  scan '{s.name}': {s.points:,} points")
    if s.bounds_min is not None:
        rng = f"; range {s.range_m[0]:.2f}-{s.range_m[1]:.2f} m" if s.range_m is not None else ""
        frame = "project frame" if getattr(s, "frame", "socs") == "project" else "SOCS"
        print(f"    bounds ({frame}, m): {_fmt_xyz(s.bounds_min)} .. {_fmt_xyz(s.bounds_max)}{rng}")
    if s.pose is not None:
        t = [row[3] for row in s.pose[:3]]
        print(f"    pose: translation {_fmt_xyz(t)} (4x4 with --json)")
    else:
        print("    pose: none (points are in " + ("a project frame)" if getattr(s, "frame", "socs") == "project"
                                               else "the scanner's frame)"))
    if s.intensity_raw_range is not None:
        lo, hi = s.intensity_raw_range
        print(f"    intensity: raw {lo:g}..{hi:g}, convention: {s.intensity_convention}")
    elif s.intensity_convention is not None:
        print(f"    intensity: convention {s.intensity_convention}")
    if s.angular_step_deg is not None:
        print(f"    angular step: {s.theta_step_deg:.4f} deg vertical (theta) x {s.phi_step_deg:.4f} deg horizontal "
              f"(phi); point spacing {s.spacing_at_10m_mm:.1f} mm at 10 m")
    print(f"    step from: {s.step_from}")
    for problem in s.problems:
        print(f"    problem: {problem}")


def cmd_convert(args) -> int:
    suffix = args.output.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise InputError(f"{args.output}: cannot write '{suffix or '(no suffix)'}'; use one of "
                         f"{', '.join(WRITE_SUFFIXES)}")
    if args.output.exists() and not args.force:
        raise InputError(f"{args.output}: already exists; choose another name or add --force")
    if args.output.resolve() == args.input.resolve():
        raise InputError(f"{args.output}: is the input file; write the conversion to a new file")
    done = convert_file(args.input, args.output, scan=args.scan)
    if done.pose_kept is None:
        kept = "intensity kept (the input has no pose)"
    elif not done.pose_kept:
        kept = f"intensity kept; the pose is not: {suffix[1:].upper()} has no place for it"
    else:
        kept = "pose and intensity kept"
    if done.lossless_copy:
        kept = "every point record, dimension and VLR copied: " + kept
    print(f"{args.output}: {done.points:,} points from {args.input} ({kept})")
    return 0

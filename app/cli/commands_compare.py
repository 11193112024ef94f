"""The ``compare`` command: whole-scan comparison of two epochs (registration, change, span profile)."""
from __future__ import annotations

import json
from pathlib import Path

from app.cli.progress import progress_bar


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
                   help="refine the target registration on the stable parts with Open3D ICP (default), PCL's NDT "
                        "(pcl_ndt3d, Debian pcl-tools) or not at all (targets)")
    p.add_argument("--no-icp", action="store_true", help="register on the targets only (= --registration targets)")
    p.add_argument("--bin-m", type=float, default=2.5, help="span profile bin length (default 2.5 m)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=cmd_compare)


def cmd_compare(args) -> int:
    from projects.compare.whole_scan import compare_epochs, save_comparison, write_outputs
    from projects.store.campaign import Campaign

    with Campaign.open(args.dir) as c:
        with progress_bar("comparing") as cb:
            summary = compare_epochs(c, args.start, args.end, method=args.method,
                                     refinement=args.registration or ("targets" if args.no_icp else "icp"),
                                     bin_m=args.bin_m, progress=cb)
        paths = write_outputs(summary, args.out)
        save_comparison(c, summary)
    public = {k: v for k, v in summary.items() if k != "_arrays"}
    if args.json:
        print(json.dumps(public, indent=2, default=float))
        return 0
    ch = public["change"]
    print(f"compared {args.start} -> {args.end} ({args.method}) in the campaign frame of {public['baseline']}")
    for lab, reg in public["registration"].items():
        if "targets" in reg:
            icp = reg.get("icp")
            print(f"  {lab}: targets RMS {reg['targets']['rms_mm']:.2f} mm" +
                  (f"; {icp.get('method', 'icp').upper()} fitness {icp['fitness']:.2f}, RMS {icp['rms_mm']:.1f} mm, iterations {icp['iterations']}, "
                   f"moved the result {icp['change_from_targets_mm']:.2f} mm" if icp else ""))
            for w in reg["targets"]["warnings"]:
                print(f"  warning: {w}")
    for part in ("stable_parts", "deck"):
        s = ch[part]
        if s["n"]:
            print(f"  {part}: median {s['median_mm']:+.2f} mm, std {s['std_mm']:.2f} mm over {s['n']} points" +
                  (f", median LoD {s['median_lod_mm']:.2f} mm" if "median_lod_mm" in s else ""))
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0

"""The ``compare`` command: whole-scan comparison of two epochs (registration, change, span profile)."""
from __future__ import annotations

import json
from pathlib import Path

from app.cli.progress import progress_bar
from common.errors import InputError
from projects.compare.whole_scan import (
    ChangeOptions,
    change_lines,
    compare_epochs,
    registration_lines,
    save_comparison,
    write_outputs,
)
from projects.store.campaign import Campaign


def _options(args):
    try:
        core: float | Path = float(args.corepoints)
    except ValueError:
        core = Path(args.corepoints)
    if args.registration_error == "measured":
        reg = None
    else:
        try:
            reg = float(args.registration_error)
        except ValueError:
            raise InputError(f"--registration-error expects metres or 'measured', got {args.registration_error!r}") \
                from None
    return ChangeOptions(normal_radii=tuple(args.normal_radii), cyl_radius=args.cyl_radius,
                         max_distance=args.max_distance, corepoints=core, registration_error=reg,
                         robust_aggr=args.robust_aggr).check()


def cmd_compare(args) -> int:
    options = _options(args)
    with Campaign.open(args.dir) as c:
        with progress_bar("comparing") as cb:
            summary = compare_epochs(c, args.start, args.end, method=args.method,
                                     refinement=args.registration or ("targets" if args.no_icp else "icp"),
                                     bin_m=args.bin_m, options=options, progress=cb)
        paths = write_outputs(summary, args.out)
        save_comparison(c, summary)
    public = {k: v for k, v in summary.items() if k != "_arrays"}
    if args.json:
        print(json.dumps(public, indent=2, default=float))
        return 0
    print(f"compared {args.start} -> {args.end} ({args.method}) in the campaign frame of {public['baseline']}")
    for _, line in registration_lines(public):
        print(f"  {line}")
    for reg in public["registration"].values():
        for w in reg.get("targets", {}).get("warnings", []):
            print(f"  warning: {w}")
    for line in change_lines(public):
        print(f"  {line}")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0

"""Camera commands: import a dual-camera displacement series, list them, cross-validate with LiDAR."""
from __future__ import annotations

from app.cli.output import dump_json, print_import, table
from common.flags import FLAG_NO_CAMERA_DATA
from projects.series.camera import crossvalidate, import_series, save_crossval, series_records, write_crossval_outputs
from projects.store.campaign import Campaign


def cmd_camera_import(args) -> int:
    with Campaign.open(args.dir) as c:
        name, series = import_series(c, args.file, name=args.name, reflector=args.reflector, column=args.column,
                                     timezone=args.timezone, unit=args.unit, positive=args.positive)
        rid = c.series.records("camera_series", name=name)[0].reflector
    s = series.summary()
    if args.json:
        dump_json({"name": name, "reflector": rid, **s})
        return 0
    print_import(f"camera series '{name}' for {rid} (sampling {s['sampling_s']:.0f} s)", s)
    return 0


def cmd_camera_list(args) -> int:
    with Campaign.open(args.dir, writable=False) as c:
        rows = series_records(c)
    if args.json:
        dump_json([r.to_dict() for r in rows])
        return 0
    table([{"name": r.name, "reflector": r.reflector, "rows": r.summary["rows"],
            "start": r.summary["start"], "end": r.summary["end"], "bad_rows": r.summary["bad_rows"],
            "file": r.original_path} for r in rows],
          ["name", "reflector", "rows", "start", "end", "bad_rows", "file"])
    return 0


def cmd_crossval(args) -> int:
    with Campaign.open(args.dir) as c:
        cv, cam = crossvalidate(c, series=args.series, reflector=args.reflector, align_at=args.align_at,
                                window_min=args.window_min)
        paths = write_crossval_outputs(cv, cam, args.out)
        save_crossval(c, cv)
    if args.json:
        dump_json(cv.to_json())
        return 0

    al = cv.alignment
    how = (f"aligned at {al['epoch']} (nearest to {al['requested']})" if al["method"] == "at-date"
           else "aligned by least squares")
    print(f"camera '{cv.series}' vs LiDAR {cv.reflector}: {cv.n_pairs} pairs of {len(cv.pairs)} epochs, {how}, "
          f"offset {cv.offset_mm:+.2f} mm")
    print(f"  {cv.statistics_text()}")
    missing = [p.epoch for p in cv.pairs if FLAG_NO_CAMERA_DATA in p.flags]
    if missing:
        print(f"  no camera data within +-{args.window_min:g} min of: {', '.join(missing[:10])}"
              + (" ..." if len(missing) > 10 else ""))
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0

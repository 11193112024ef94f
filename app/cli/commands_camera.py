"""Camera commands: import a dual-camera displacement series, list them, cross-validate with LiDAR."""
from __future__ import annotations

from app.cli.args import add_dir, add_json, input_file, output_folder
from app.cli.commands_analysis import print_import
from app.cli.output import dump_json, table
from common.flags import FLAG_NO_CAMERA_DATA


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
    q.set_defaults(func=cmd_camera_import)
    q = actions.add_parser("list", help="list the imported series")
    add_dir(q)
    add_json(q)
    q.set_defaults(func=cmd_camera_list)

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
    p.set_defaults(func=cmd_crossval)


def cmd_camera_import(args) -> int:
    from projects.series.camera import import_series
    from projects.store.campaign import Campaign

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
    from projects.series.camera import series_records
    from projects.store.campaign import Campaign

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
    from projects.series.camera import crossvalidate, save_crossval, write_crossval_outputs
    from projects.store.campaign import Campaign

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

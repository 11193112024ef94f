"""Explaining the displacements: environment series, events, and the analysis."""
from __future__ import annotations

from app.cli.args import LazyChoices, add_dir, add_json, input_file, output_folder
from app.cli.commands_campaign import open_campaign
from app.cli.output import dump_json, table


def register(sub) -> None:
    kinds = LazyChoices("projects.series.environment", "KINDS")
    event_kinds = LazyChoices("projects.series.environment", "EVENT_KINDS")

    p = sub.add_parser("env", help="environment series: temperature, sun, rain, snow, humidity",
                       description="Import or list the environment series the analysis explains the "
                                   "displacements with.")
    es = p.add_subparsers(dest="env_command", metavar="ACTION")
    es.required = True
    q = es.add_parser("import", help="import a series (CSV/text; the file is kept read-only in the campaign)")
    add_dir(q)
    input_file(q, "file", help="the series file: a time column and a value column (CSV or text; separated by "
                                "commas, semicolons, tabs or spaces; decimal commas read; bad rows left out and "
                                "counted)")
    q.add_argument("--kind", required=True, choices=kinds, metavar="KIND", help="what it measures: %(choices)s")
    q.add_argument("--name", default=None, help="series name (default: the file name)")
    q.add_argument("--column", default=None, help="the value column when the header does not tell")
    q.add_argument("--unit", default=None, help="the values' unit when the header does not tell (degC, degF, K, "
                                                 "W/m2, mm, cm, %%...)")
    q.add_argument("--timezone", default=None, metavar="ZONE",
                   help="the zone of times without an offset (IANA name or +hh:mm; default: the campaign's, "
                        "see 'status')")
    q.set_defaults(func=cmd_env_import)
    q = es.add_parser("list", help="the imported series")
    add_dir(q)
    add_json(q)
    q.set_defaults(func=cmd_env_list)

    p = sub.add_parser("event", help="construction steps, loads, repairs: what the analysis explains",
                       description="Add or list the events (construction steps, loads, repairs) whose steps and "
                                   "creep the analysis fits.")
    vs = p.add_subparsers(dest="event_command", metavar="ACTION")
    vs.required = True
    q = vs.add_parser("add", help="add an event")
    add_dir(q)
    q.add_argument("--date", required=True, help="ISO 8601 date or date-time")
    q.add_argument("--kind", required=True, choices=event_kinds, metavar="KIND", help="one of %(choices)s")
    q.add_argument("--label", required=True, help="what happened, as the report and plots show it")
    q.add_argument("--load-kn-m", type=float, default=None, help="distributed load added, kN/m")
    q.set_defaults(func=cmd_event_add)
    q = vs.add_parser("list", help="the events, by date")
    add_dir(q)
    add_json(q)
    q.set_defaults(func=cmd_event_list)

    p = sub.add_parser("prediction", help="the design prediction of each target, aligned to the measurements",
                       description="Import the design prediction (e.g. a finite-element curve) of the targets.")
    ps = p.add_subparsers(dest="prediction_command", metavar="ACTION")
    ps.required = True
    q = ps.add_parser("import", help="import a prediction CSV and align it to the measurements",
                      description="CSV with a 'date' (or 'age_days', with the casting date set) column "
                                  "and one column per target id in mm positive up, or long form with "
                                  "'reflector' and 'value_mm'. Aligned at a date or by least squares "
                                  "(default). 'limit DIR --rule prediction:TOL_MM' flags departures.")
    add_dir(q)
    input_file(q, "file", help="the prediction CSV")
    g = q.add_mutually_exclusive_group()
    g.add_argument("--align-at", default=None, help="align at the epoch nearest this date")
    g.add_argument("--align", choices=("lsq",), default=None, help="align by weighted least squares (lsq)")
    q.set_defaults(func=cmd_prediction_import)

    p = sub.add_parser("analyse", help="temperature effect, event steps and creep, trend and projection per target",
                       description="Fits every measurement target's history: a thermal coefficient (mm/degC, "
                                   "window and lag chosen by AICc), each event's immediate step and the creep "
                                   "that follows (ACI 209 time shape, creep coefficient with sigma), a trend, and "
                                   "a projection to a horizon with the date the warning level is reached at this "
                                   "rate. Writes OUTDIR/analysis.json and one figure per target.")
    add_dir(p)
    output_folder(p, "--out", required=True, metavar="OUTDIR", help="output folder (created when missing)")
    p.add_argument("--horizon-days", type=float, default=365.0, help="projection horizon after the last epoch (365)")
    p.add_argument("--long-term-factor", type=float, default=None,
                   help="design code's long-term factor on dead-load steps (the dissertation cites 2 for KDS)")
    p.add_argument("--reference-temperature", type=float, default=None,
                   help="temperature the corrected series refer to (default: the median at the epochs), degC")
    add_json(p, help="print analysis.json instead of the table")
    p.set_defaults(func=cmd_analyse)


def cmd_env_import(args) -> int:
    from projects.series.environment import import_env

    with open_campaign(args.dir) as c:
        name, s = import_env(c, args.file, kind=args.kind, name=args.name, column=args.column, unit=args.unit,
                             timezone=args.timezone)
    print_import(f"{args.kind} series {name!r}", s.summary())
    return 0


def print_import(what: str, summ: dict) -> None:
    """The lines an import of a series prints: what was read, how the times were read, what was left out."""
    print(f"imported {what}: {summ['rows']} rows from {summ['start']} to {summ['end']}, column "
          f"'{summ['column']}' in {summ['unit_read']}, {summ['gaps']} gap(s), {summ['missing_values']} missing "
          f"value(s)")
    print(f"  times: {summ['times']}")
    if summ["bad_rows"]:
        print(f"  {summ['bad_rows']} bad row(s) of {summ['rows_in_file']} left out (could not be read):")
    for line in summ["first_bad_lines"][:5]:
        print(f"    {line}")
    if summ["bad_rows"] > 5:
        print(f"    ... and {summ['bad_rows'] - 5} more")
    for note in summ["notes"]:
        if "could not be read" not in note:
            print(f"  note: {note}")


def cmd_env_list(args) -> int:
    from projects.series.environment import env_records

    with open_campaign(args.dir, writable=False) as c:
        rows = env_records(c)
    if args.json:
        dump_json([r.to_dict() for r in rows])
        return 0
    table([{"name": r.name, "kind": r.kind, "unit": r.options["unit"], "rows": r.summary["rows"],
            "start": (r.summary["start"] or "")[:16], "end": (r.summary["end"] or "")[:16],
            "bad_rows": r.summary["bad_rows"]} for r in rows], ["name", "kind", "unit", "rows", "start", "end",
                                                                "bad_rows"])
    return 0


def cmd_event_add(args) -> int:
    from projects.series.environment import add_event

    with open_campaign(args.dir) as c:
        eid = add_event(c, date=args.date, kind=args.kind, label=args.label, load_kn_m=args.load_kn_m)
    print(f"event {eid} added: {args.kind} '{args.label}' on {args.date}")
    return 0


def cmd_event_list(args) -> int:
    from projects.series.environment import events

    with open_campaign(args.dir, writable=False) as c:
        rows = [e.to_dict() for e in events(c)]
    if args.json:
        dump_json(rows)
    else:
        table(rows, ["id", "date", "kind", "label", "load_kn_m"])
    return 0


def cmd_prediction_import(args) -> int:
    from projects.series.predictions import import_prediction

    with open_campaign(args.dir) as c:
        out = import_prediction(c, args.file, align_at=args.align_at, lsq=args.align == "lsq")
    how = f"at {args.align_at}" if args.align_at else "by least squares"
    table([{"reflector": k, **v} for k, v in sorted(out.items())], ["reflector", "offset_mm", "residual_rms_mm", "pairs"])
    print(f"prediction imported for {len(out)} target(s), aligned {how}")
    return 0


def cmd_analyse(args) -> int:
    from projects.analysis.run import write_analysis

    with open_campaign(args.dir, writable=False) as c:
        doc, paths = write_analysis(c, args.out, horizon_days=args.horizon_days,
                                    long_term_factor=args.long_term_factor,
                                    reference_temperature=args.reference_temperature)
    if args.json:
        dump_json(doc)
        return 0
    print_analysis(doc)
    print(f"wrote {len(paths)} file(s) to {args.out}")
    return 0


def _pm(v, s, fmt="{:+.2f}", sfmt="{:.2f}") -> str:
    if v is None:
        return "-"
    return fmt.format(v) + ("" if s is None else " ± " + sfmt.format(s))


def print_analysis(doc: dict) -> None:
    """The analysis target by target: thermal coefficient and trend, each event with what its numbers mean,
    the projection and the notes; then the warnings."""
    numbers = {(e["date"][:10], e["label"]): k for k, e in enumerate(doc["events"], start=1)}
    for t in doc["targets"]:
        thermal = ("no thermal term" if t["thermal_mm_per_degC"] is None else
                   f"thermal {_pm(t['thermal_mm_per_degC'], t['thermal_sigma'], '{:+.3f}', '{:.3f}')} mm/°C")
        trend = ("no trend" if t["trend_mm_per_year"] is None else
                 f"trend {_pm(t['trend_mm_per_year'], t['trend_sigma'], '{:+.1f}', '{:.1f}')} mm/year")
        print(f"{t['reflector']}  {thermal}, {trend}, {t['epochs']} epochs")
        if t.get("along_mm_per_degC") is not None:
            print(f"    along the span {_pm(t['along_mm_per_degC'], t['along_sigma'], '{:+.3f}', '{:.3f}')} mm/°C")
        if t.get("along_note") and t.get("along_mm_per_degC") is not None:
            print(f"      note: {t['along_note']}")
        for e in t["events"]:
            k = numbers.get((e["date"][:10], e["label"]), "-")
            text = f"    event {k} {e['label']} ({e['date'][:10]}): step {_pm(e['step_mm'], e['step_sigma_mm'])} mm"
            if e["creep_coefficient"] is not None:
                text += f", creep coefficient {_pm(e['creep_coefficient'], e['creep_coefficient_sigma'], '{:.2f}')}"
            print(text)
            if e["note"]:
                print(f"      note: {e['note']}")
        proj = t["projection"] or {}
        if proj.get("warning"):
            print(f"    projection: {proj['warning']}")
        for n in t["notes"]:
            print(f"    note: {n}")
    for w in doc["warnings"]:
        print(f"warning: {w}")

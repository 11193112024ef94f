"""Explaining the displacements: environment series, events, and the analysis."""
from __future__ import annotations

from app.cli.campaigns import open_campaign
from app.cli.output import dump_json, print_import, table
from projects.series.environment import add_event, env_records, events, import_env
from projects.series.predictions import import_prediction


def cmd_env_import(args) -> int:
    with open_campaign(args.dir) as c:
        name, s = import_env(c, args.file, kind=args.kind, name=args.name, column=args.column, unit=args.unit,
                             timezone=args.timezone)
    print_import(f"{args.kind} series {name!r}", s.summary())
    return 0



def cmd_env_list(args) -> int:
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
    with open_campaign(args.dir) as c:
        eid = add_event(c, date=args.date, kind=args.kind, label=args.label, load_kn_m=args.load_kn_m)
    print(f"event {eid} added: {args.kind} '{args.label}' on {args.date}")
    return 0


def cmd_event_list(args) -> int:
    with open_campaign(args.dir, writable=False) as c:
        rows = [e.to_dict() for e in events(c)]
    if args.json:
        dump_json(rows)
    else:
        table(rows, ["id", "date", "kind", "label", "load_kn_m"])
    return 0


def cmd_prediction_import(args) -> int:
    with open_campaign(args.dir) as c:
        out = import_prediction(c, args.file, align_at=args.align_at, lsq=args.align == "lsq")
    how = f"at {args.align_at}" if args.align_at else "by least squares"
    table([{"reflector": k, **v} for k, v in sorted(out.items())], ["reflector", "offset_mm", "residual_rms_mm", "pairs"])
    print(f"prediction imported for {len(out)} target(s), aligned {how}")
    return 0


def cmd_analyse(args) -> int:
    # local: the analysis's figures (matplotlib) cost env, event and prediction 0.33 s of start-up (measured)
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

"""The parsers of the commands explaining the displacements: environment series, events, and the analysis.

They name each command's function in app.cli.commands_analysis (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import LazyChoices, add_dir, add_json, input_file, output_folder


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
    q.set_defaults(func="cmd_env_import")
    q = es.add_parser("list", help="the imported series")
    add_dir(q)
    add_json(q)
    q.set_defaults(func="cmd_env_list")

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
    q.set_defaults(func="cmd_event_add")
    q = vs.add_parser("list", help="the events, by date")
    add_dir(q)
    add_json(q)
    q.set_defaults(func="cmd_event_list")

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
    q.set_defaults(func="cmd_prediction_import")

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
    p.set_defaults(func="cmd_analyse")

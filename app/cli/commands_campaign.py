"""Campaign commands: init, add-epoch, add-fine, plan, process, displacements, status, reflector, limit, export, demo."""
from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path

from app.cli.campaigns import open_campaign, setup_date, setup_of
from app.cli.output import dump_json, table
from app.cli.parsers.campaign import STATUS_EPOCHS
from app.cli.progress import progress_bar
from common.errors import InputError
from common.files import (
    stale_temp_files,
    write_atomic,
)
from common.flags import FLAG_DEPARTS, describe, first_action, severity, summary, worst
from lidar.io.poses import FileFrame, file_frames, parse_vector, pose_from_origin, read_pose_file
from lidar.layout import read_layout_csv
from lidar.plan import without_closure
from lidar.scanner_catalogue import DEFAULT_SCANNER, get_scanner
from projects.outputs.exports import export
from projects.outputs.visit_overview import visit_overview
from projects.processing.parameters import DEFAULTS
from projects.results.corrections import instrument_line
from projects.results.state import epoch_states
from projects.results.table import damaged_line, displacement_table, to_csv, written_rows
from projects.store.campaign import Campaign, parse_datetime


def _given_pose(args):
    """The pose the user gave (--pose FILE or --origin X,Y,Z [--up]) as a FileFrame, or None."""
    pose, origin, up = getattr(args, "pose", None), getattr(args, "origin", None), getattr(args, "up", None)
    if pose is not None and origin is not None:
        raise InputError("give the scanner pose with --pose FILE or its position with --origin X,Y,Z, not both")
    if up is not None and origin is None:
        raise InputError("--up goes with --origin (a pose file already holds the scanner's vertical)")
    if pose is not None:
        return FileFrame(pose=read_pose_file(pose), carry=True, source="pose", given=str(pose))
    if origin is not None:
        m = pose_from_origin(parse_vector(origin, "--origin"), None if up is None else parse_vector(up, "--up"))
        return FileFrame(pose=m, carry=True, source="origin", given=origin + (f" up {up}" if up else ""))
    return None


def _frames_of(args):
    """The import's file reader: each file checked and its set-ups' frames worked out (see lidar.io.poses)."""
    given = _given_pose(args)  # a bad pose file is refused before any scan is read

    def frames_of(path: Path, fallback):
        with progress_bar(f"checking {path.name}") as cb:
            frames = file_frames(path, given=given, fallback=fallback, progress=cb)
        dropped, points = sum(f.dropped_points for f in frames), sum(f.points for f in frames)
        if dropped:
            print(f"note: {path}: {dropped:,} of {dropped + points:,} points ({100 * dropped / (dropped + points):.1f} "
                  "%) have a NaN or infinite coordinate and are left out")
        return frames
    return frames_of




def cmd_init(args) -> int:
    profile = get_scanner(args.scanner or DEFAULT_SCANNER)
    layout = read_layout_csv(args.layout, default_diameter_m=args.target_diameter_mm / 1000.0)
    with Campaign.create(args.dir, name=args.name, layout=layout, span_m=args.span_m, profile=profile,
                         timezone=args.timezone) as c:
        print(f"created campaign '{c.name}' in {args.dir} with {len(layout)} reflectors "
              f"({len(layout.ids_in('reference'))} reference, {len(layout.ids_in('measurement'))} measurement), "
              f"time zone {c.timezone}")
        for w in c.layout_warnings():
            print(f"warning: {w}")
    return 0


def cmd_add_epoch(args) -> int:
    when = parse_datetime(args.date)
    label = args.label or when[:10]
    profile = get_scanner(args.scanner) if args.scanner else None
    frames_of = _frames_of(args)
    with open_campaign(args.dir) as c:
        c.add_epoch(label, when, args.coarse, args.fine, notes=args.notes, frames_of=frames_of,
                    allow_date=args.allow_date)
        if profile is not None:
            c.set_profile(profile, epoch=label)
        note = c.baseline_note(label)
        setups = c.setups(label)
    print(f"added epoch {label} ({when}) with {1 + len(args.fine)} file(s)"
          + (f": set-ups {', '.join(map(str, setups))} (one per scan position in the file)" if len(setups) > 1 else ""))
    if note:
        print(f"note: {note}")
    return 0


def cmd_add_setup(args) -> int:
    profile = get_scanner(args.scanner) if args.scanner else None
    frames_of = _frames_of(args)
    with open_campaign(args.dir) as c:
        new = c.add_setup(args.epoch, args.coarse, args.fine, frames_of=frames_of)
        if profile is not None:
            for k in new:
                c.set_profile(profile, epoch=args.epoch, setup=k)
    which = f"set-up {new[0]}" if len(new) == 1 else f"set-ups {', '.join(map(str, new))}"
    print(f"added {which} to epoch {args.epoch} with {1 + len(args.fine)} file(s); plan it with "
          f"'bridgesurvey plan {args.dir} --epoch {args.epoch} --setup {new[0]} --out plan.json'")
    return 0


def cmd_add_fine(args) -> int:
    frames_of = _frames_of(args)
    with open_campaign(args.dir) as c:
        c.epoch(args.epoch)
        if args.setup is not None:
            c.check_setup(args.epoch, args.setup)
        c.import_files(args.epoch, args.files, "fine", setup=args.setup, frames_of=frames_of)
        several = len(c.setups(args.epoch)) > 1
        where = {k for f in c.files(args.epoch, "fine", setup=None) if str(f.original_path) in
                 {str(p.resolve()) for p in args.files} for k in f.setups}
    print(f"added {len(args.files)} fine scan file(s) to epoch {args.epoch}"
          + (f", set-up {', '.join(map(str, sorted(where)))}" if several else ""))
    return 0


def cmd_plan(args) -> int:
    # local: the processing (the pipeline, scikit-image) costs init, reflector, limit, displacements 0.18 s (measured)
    from projects.processing.stages import plan_epoch, plan_visit_epoch
    with open_campaign(args.dir) as c:
        c.epoch(args.epoch)
        setup = setup_of(c, args)
        several = len(c.setups(args.epoch)) > 1
        with progress_bar("planning") as cb:
            if several:  # the visit's set-ups are planned together: the whole visit is shown
                plans, summaries = plan_visit_epoch(c, args.epoch, progress=cb)
                plan = plans[setup] if setup in plans else plan_epoch(c, args.epoch, setup=setup, progress=cb)
            else:
                plan, plans, summaries = plan_epoch(c, args.epoch, setup=setup, progress=cb), {}, {}
        overview = visit_overview(plans, summaries)
        if args.no_closure:
            plan = without_closure(plan)
        if args.sheet is not None:
            # local: the sheet's matplotlib and reportlab cost the other campaign commands 0.5 s (measured)
            from projects.outputs.field_sheet import write_field_sheet

            write_field_sheet(plan, args.sheet, campaign_name=c.name, preview=c.map_preview(args.epoch, setup),
                              epoch_date=setup_date(c, args.epoch, setup), visit=overview)
        warnings = c.layout_warnings(args.epoch)
    doc = plan.to_json()
    if several:
        doc.update(setup=setup, **({"visit": summaries[setup]} if summaries.get(setup) else {}))
    write_atomic(args.out, json.dumps(doc, indent=2))
    print(f"wrote {args.out}: {len(plan.rois)} windows, {plan.total_seconds / 60:.1f} min"
          + (f" (set-up {setup})" if several else "") + (f"; field sheet {args.sheet}" if args.sheet else ""))
    for line in overview:
        print(line)
    for w in [*plan.warnings, *warnings]:
        print(f"warning: {w}")
    return 0



#: Exit status of 'process' when an epoch was processed but carries a problem flag (no trustworthy result).
EXIT_PROBLEM = 3


def cmd_process(args) -> int:
    # local: the processing (the pipeline, scikit-image) costs init, reflector, limit, displacements 0.18 s (measured)
    from projects.processing.stages import process
    with open_campaign(args.dir) as c:
        _check_verdicts_allow(c, args)
        had_displacements = {e.label for e in c.epochs() if c.displacement_set(e.label) is not None}
        with progress_bar("processing") as cb:
            summary = process(c, args.epoch, progress=cb)
        states = epoch_states(c)
    rows = _process_rows(summary, states, had_displacements)
    if args.json:
        dump_json({"baseline": summary.baseline, "epochs": rows, "displacements_updated": summary.displacement_epochs})
    else:
        done = [r for r in rows if r["action"] != "up-to-date"]
        if done:
            table(done, ["epoch", "action", "state", "note"])
        print(_process_summary(rows, summary.baseline))
    if summary.failed:
        archived = [o.epoch for o in summary.failed if o.archived]
        if len(archived) < 2:  # one visit's own sentence says it best
            archived = []
        if archived:  # one line for them all, not one near-identical sentence per visit
            span = f"{archived[0]} … {archived[-1]}" if len(archived) > 2 else " and ".join(archived)
            print(f"bridgesurvey: error: {len(archived)} epoch(s) ({span}) need scans archived out of the campaign "
                  f"folder to be processed again; bring them back with 'bridgesurvey archive {args.dir} --restore' "
                  "(--epoch LABEL for one) and run the command again; the results stored so far are kept",
                  file=sys.stderr)
        other = [o for o in summary.failed if o.epoch not in archived]
        if other:
            print(f"bridgesurvey: error: {len(other)} epoch(s) failed: " +
                  "; ".join(f"{o.epoch}: {o.message}" for o in other), file=sys.stderr)
        return 1
    if summary.problems:
        print(f"bridgesurvey: {len(summary.problems)} epoch(s) without a trustworthy result: " +
              "; ".join(f"{lab}: {flag}" for lab, flag in summary.problems.items()), file=sys.stderr)
        return EXIT_PROBLEM
    return 0


def _check_verdicts_allow(c, args) -> None:
    """Refuse (one line, nothing changed) to process an epoch whose check asked for a re-scan not yet added,
    unless ``--accept-check`` (then the acceptance is logged)."""
    # local: the processing (the pipeline, scikit-image) costs init, reflector, limit, displacements 0.18 s (measured)
    from projects.onsite.check import pending_rescans
    for label in args.epoch or ():
        c.epoch(label)
    pending = pending_rescans(c, args.epoch or [e.label for e in c.epochs()])  # what 'process' brings up to date
    if not pending:
        return
    if not args.accept_check:
        what = "; ".join(f"{label}: the check asked to {v.line()}" for label, v in pending.items())
        raise InputError(f"{what}; add the re-scan's fine scans (bridgesurvey add-fine {args.dir} --epoch "
                         f"{next(iter(pending))} FILE...), or process as it is with --accept-check")
    for label in pending:
        c.accept_check(label)


def _process_rows(summary, states: dict, had_displacements: set) -> list[dict]:
    """One row per epoch: what processing did to it (its stage-1 action, or its displacements) and its state.

    An epoch whose centroids were measured earlier (by 'check') and whose displacements were computed
    now is 'processed', one whose displacements were recomputed 'displacements', not 'up-to-date'.
    """
    updated = set(summary.displacement_epochs)
    outcomes = {o.epoch: o for o in summary.outcomes}
    rows = []
    for lab in list(outcomes) + [lab for lab in states if lab in updated and lab not in outcomes]:
        o = outcomes.get(lab)
        action, message = (o.action, o.message) if o is not None else ("up-to-date", "")
        if action == "up-to-date" and lab in updated:
            why = ("the campaign's field model was re-fitted with the new epochs (range walk, scales, drift)"
                   if summary.displacement_reasons.get(lab) == "field" else
                   "parameters, baseline, reflectors or the air's series changed")
            action, message = (("displacements", f"recomputed ({why})")
                               if lab in had_displacements else
                               ("processed", "displacements computed from the centroids measured earlier "
                                             "(e.g. by 'check')"))
        st = states.get(lab)
        serious = [f for f in (st.flags if st else ()) if severity(f) in ("warning", "problem")]
        note = "; ".join(x for x in (message, ", ".join(serious)) if x)
        rows.append({"epoch": lab, "action": action, "message": message,
                     "state": st.state if st else "", "note": note})
    return rows


def _process_summary(rows: list[dict], baseline) -> str:
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["action"]] = counts.get(r["action"], 0) + 1
    order = ("measured", "planned", "processed", "displacements", "failed")
    words = {"displacements": "with displacements recomputed"}
    parts = [f"{counts[a]} {words.get(a, a)}" for a in order if counts.get(a)]
    up = counts.get("up-to-date", 0)
    if up:
        parts.append(f"{up} up to date")
    head = f"{len(rows)} epoch(s): " + ", ".join(parts) if parts else "no epoch yet"
    if not any(counts.get(a) for a in order):
        head = "nothing to do: " + head
    return f"{head}; baseline {baseline or '(none yet)'}"


def cmd_displacements(args) -> int:
    with open_campaign(args.dir, writable=False) as c:
        rows = displacement_table(c)
        damaged = damaged_line(c)
    if damaged:  # never rows dropped without a word (the CSV itself keeps its contract: a header, then rows)
        print(f"bridgesurvey: warning: {damaged}", file=sys.stderr)
    text = to_csv(rows) if args.format == "csv" else json.dumps(written_rows(rows), indent=2)
    if args.out:
        write_atomic(args.out, text)
        print(f"wrote {len(rows)} rows to {args.out}")
    else:
        sys.stdout.write(text if text.endswith("\n") else text + "\n")
    return 0


def cmd_status(args) -> int:
    # local: the processing (the pipeline, scikit-image) costs init, reflector, limit, displacements 0.18 s (measured)
    from projects.results.status import campaign_status, storage_line
    with open_campaign(args.dir, writable=False) as c:
        data = campaign_status(c)
        left = [p.name for p in stale_temp_files(c.folder)]
    if left:
        print(f"note: temporary file(s) a killed command left: {', '.join(left)} (the next writing command on the "
              "campaign removes them)", file=sys.stderr)
    if args.json:
        dump_json(data)
        return 0
    epochs = data["epochs"]
    print(f"campaign '{data['name']}', span {data['span_m'] or '?'} m, time zone {data['timezone']}, "
          f"baseline {data['baseline'] or '-'}, {len(epochs)} epoch(s)")
    shown = epochs if args.all else epochs[-STATUS_EPOCHS:]
    table([{**e, "flags": describe(e["flag_list"]) if args.verbose else _short(summary(e["flag_list"])),
            "scale": _scale_text(e, data["baseline"])} for e in shown],
          ["epoch", "datetime", "state", "stale", "scale", "flags"])
    if len(shown) < len(epochs):
        print(f"(last {len(shown)} of {len(epochs)} epochs; --all for every epoch)")
    levels = {e["epoch"]: worst(e["flag_list"]) for e in epochs}
    tally = {s: sum(w == s for w in levels.values()) for s in ("problem", "warning", "info")}
    print(f"epochs with problems: {tally['problem']}, with warnings: {tally['warning']}, "
          f"with information flags only: {tally['info']}")
    for e in epochs:
        if e["rescan"]:
            print(f"CHECK of {e['epoch']}: {e['check']}; next: the re-scan (add-fine), or process --accept-check")
    for e in epochs:
        level = levels[e["epoch"]]
        if level in ("problem", "warning"):
            serious = [f for f in e["flag_list"] if severity(f) in ("problem", "warning")]
            said = f"{level.upper()} in {e['epoch']}: " + ("; ".join(serious) if args.verbose else summary(serious))
            todo = f"  action: {first_action(serious)}"
            print(said if args.verbose else _line(said))
            print(todo if args.verbose else _line(todo))
    rev = data.get("revisions")
    if rev and rev["revised"]:  # values already stored (perhaps reported) that processing changed: never silent
        lines = rev["revised"] if args.verbose else rev["revised"][:STATUS_REVISIONS]
        print(f"revised by the processing of {rev['time'][:16].replace('T', ' ')}: {len(rev['revised'])} value(s)"
              + ("" if len(lines) == len(rev["revised"]) else " (--verbose for all)"))
        for r in lines:
            text = f"  {r['epoch']} {r['target']}: {r['old']} → {r['new']} ({r['why']})"
            print(text if args.verbose else _line(text))
    if data.get("instrument"):
        print("instrument (the campaign's field model): " + instrument_line(data["instrument"]))
    print("latest displacement of each measurement target:")
    table(data["targets"], ["reflector", "epoch", "displacement_mm", "sigma_mm", "state", "warning_mm", "alarm_mm",
                            "flags"])
    alarms = [t["reflector"] for t in data["targets"] if t["state"] == "alarm"]
    if alarms:
        print(f"ALARM: {', '.join(alarms)}")
    for w in data["warnings"]:
        print(f"warning: {w}")
    print(storage_line(data["storage"]))
    if data["unlisted_files"]:
        print(f"warning: {len(data['unlisted_files'])} file(s) in the campaign folder that the database does not list "
              f"(kept; 'bridgesurvey repair {args.dir}' registers them again): {', '.join(data['unlisted_files'])}")
    return 0


#: Revisions ``status`` lists without --verbose.
STATUS_REVISIONS = 3

#: The flags column of a visit's line in ``status`` (its line stays within 120 characters; --verbose for all).
FLAGS_WIDTH = 56


#: A line of ``status`` without --verbose, at most (characters).
STATUS_LINE = 120


def _line(text: str) -> str:
    return text if len(text) <= STATUS_LINE else text[:STATUS_LINE - 1].rstrip("; ,") + "…"


def _short(text: str) -> str:
    return text if len(text) <= FLAGS_WIDTH else text[:FLAGS_WIDTH - 1].rstrip("; ") + "…"


def _scale_text(e: dict, baseline: str | None) -> str:
    """``+3.1±0.8 ppm`` (the range scale the field model found for the epoch), ``-`` without one."""
    if e.get("scale_ppm") is None:
        return "-"
    if e["epoch"] == baseline:
        return "0 (baseline)"
    return f"{e['scale_ppm']:+.1f}±{e['scale_sigma_ppm']:.1f} ppm"


def _xyz(text: str):

    try:
        v = [float(x) for x in text.split(",")]
        if len(v) != 3:
            raise ValueError
        return v
    except ValueError:
        raise InputError(f"--xyz expects x,y,z in metres, got {text!r}") from None


def cmd_reflector(args) -> int:
    with open_campaign(args.dir, writable=args.action != "list") as c:
        if args.action == "list":
            rows = [r.to_dict() for r in c.reflectors()]
            if args.json:
                dump_json(rows)
            else:
                table(rows, ["id", "group", "x", "y", "z", "diameter_m", "installed", "retired", "replaces"])
        elif args.action == "add":
            c.add_reflector(args.id, args.group, _xyz(args.xyz), diameter_m=args.diameter_mm / 1000.0,
                            installed=args.installed)
            print(f"added {args.group} reflector {args.id}")
        elif args.action == "retire":
            c.retire_reflector(args.id, args.date)
            print(f"retired {args.id}")
        else:
            c.replace_reflector(args.old, args.new, args.date, xyz=_xyz(args.xyz) if args.xyz else None)
            print(f"{args.new} replaces {args.old} from {args.date}; its history continues {args.old}'s")
    return 0


def cmd_limit(args) -> int:
    if args.rule.startswith("prediction:"):
        return _prediction_tolerance(args)
    with open_campaign(args.dir) as c:
        c.set_limit(args.reflector, args.rule)
        lim = c.limit_for(args.reflector if args.reflector != "*" else "*")
    print(f"limit for {args.reflector}: warning {lim.warning_mm:.2f} mm, alarm {lim.alarm_mm:.2f} mm ({lim.rule})")
    return 0


def _prediction_tolerance(args) -> int:
    try:
        tol = float(args.rule.split(":", 1)[1])
    except ValueError:
        tol = float("nan")
    if not (tol == tol and 0 < tol < 1e4):
        raise InputError(f"limit rule {args.rule!r}: the tolerance must be a positive number of millimetres")
    with open_campaign(args.dir) as c:
        if args.reflector != "*":
            c.reflector(args.reflector)
        tols = dict(c.settings().get("prediction_tolerance_mm") or {})
        tols[args.reflector] = tol
        c.set_setting("prediction_tolerance_mm", tols)
    print(f"a displacement departing from the design prediction by more than {tol:g} mm is flagged "
          f"({FLAG_DEPARTS}) for {'every target' if args.reflector == '*' else args.reflector}")
    return 0


def cmd_settings(args) -> int:
    # local: the processing (the pipeline, scikit-image) costs init, reflector, limit, displacements 0.18 s (measured)
    from projects.processing.stages import parameters, set_parameter, stale_epochs
    if args.key == "scanner":
        return _set_scanner(args)
    if args.key == "timezone":
        return _set_timezone(args)
    if args.epoch is not None:
        raise InputError("--epoch goes with the 'scanner' setting only")
    if args.key is None:
        with open_campaign(args.dir, writable=False) as c:
            params = parameters(c)
            params["baseline"] = c.settings().get("baseline")
            params["scanner"] = c.profile.name
            params["timezone"] = c.timezone
        defaults = {**DEFAULTS, "timezone": "UTC"}
        table([{"key": k, "value": v, "default": defaults.get(k)} for k, v in params.items()],
              ["key", "value", "default"])
        return 0
    with open_campaign(args.dir) as c:
        old_baseline = c.settings().get("baseline")
        set_parameter(c, args.key, args.value)
        stale = stale_epochs(c)
    if args.key == "baseline" and (args.value or None) != old_baseline:
        print(f"warning: the baseline changes from {old_baseline or '(first measured epoch)'} to "
              f"{args.value or '(first measured epoch)'}: every displacement of the campaign is re-referenced "
              "at the next 'bridgesurvey process' (the change is in the campaign log)", file=sys.stderr)
    print(f"{args.key} = {args.value}; {len(stale)} epoch(s) need processing for their centroids "
          "(displacements follow); run 'bridgesurvey process'")
    return 0


def _set_timezone(args) -> int:
    if args.epoch is not None:
        raise InputError("--epoch goes with the 'scanner' setting only")
    with open_campaign(args.dir) as c:
        old = c.timezone
        c.set_timezone(args.value or "UTC")
        print(f"timezone = {c.timezone} (was {old}): imports from now on read times without an offset in it; "
              "series imported before keep the zone they were read in")
    return 0


def _set_scanner(args) -> int:
    # local: the processing (the pipeline, scikit-image) costs init, reflector, limit, displacements 0.18 s (measured)
    from projects.processing.stages import stale_epochs
    if not args.value:
        raise InputError("give the scanner: a name from 'bridgesurvey scanners' or a profile .json")
    profile = get_scanner(args.value)
    with open_campaign(args.dir) as c:
        c.set_profile(profile, epoch=args.epoch)
        stale = stale_epochs(c)
    where = f"epoch {args.epoch}" if args.epoch else "the campaign"
    print(f"scanner of {where} = {profile.name}; {len(stale)} epoch(s) need processing; run 'bridgesurvey process'")
    return 0


def cmd_export(args) -> int:
    with open_campaign(args.dir, writable=False) as c:
        path = export(c, args.out)
        damaged = damaged_line(c)
    print(f"wrote {path}")
    if damaged:
        print(f"bridgesurvey: warning: {damaged}", file=sys.stderr)
    return 0


def cmd_demo(args) -> int:
    # local: the simulator and the report cost every other campaign command 0.3 s (measured)
    from projects.demo import build_demo
    with progress_bar("demo campaign") as cb:
        result = build_demo(args.dir, weeks=args.weeks, seed=args.seed, progress=cb)
    print(result.summary())
    folder = shlex.quote(str(args.dir))
    print(f"open it in the application: ./run gui {folder} (from the source folder; installed: bridgesurvey-gui "
          f"{folder}); on the command line: bridgesurvey status {folder}")
    return 0

"""Field commands: scanners (the instrument catalogue), field-sheet, check (before leaving the site), stations."""
from __future__ import annotations

import json
import math
import sys

from app.cli.campaigns import open_campaign, setup_date, setup_of
from app.cli.output import dump_json, table
from app.cli.progress import progress_bar
from common.errors import InputError, SurveyError
from common.files import write_atomic
from lidar.figures import save_figure
from projects.onsite.check import check_epoch, check_visit
from projects.onsite.station_pairs import above, propose_pair, propose_three, short_of
from projects.onsite.stations import (
    advise_stations,
    plan_from_positions,
    positions_visit_json,
    read_area_csv,
    station_map_figure,
)
from projects.outputs.field_sheet import write_field_sheet
from projects.outputs.visit_overview import visit_overview
from projects.processing.stages import plan_epoch, plan_visit_epoch


def cmd_field_sheet(args) -> int:
    with open_campaign(args.dir) as c:
        c.epoch(args.epoch)
        setup = setup_of(c, args)
        with progress_bar("planning") as cb:
            if len(c.setups(args.epoch)) > 1:  # the whole visit, set-up by set-up, heads the sheet
                plans, summaries = plan_visit_epoch(c, args.epoch, progress=cb)
                plan = plans[setup] if setup in plans else plan_epoch(c, args.epoch, setup=setup, progress=cb)
            else:
                plan, plans, summaries = plan_epoch(c, args.epoch, setup=setup, progress=cb), {}, {}
        preview = c.map_preview(args.epoch, setup)
        path = write_field_sheet(plan, args.out, campaign_name=c.name, preview=preview,
                                 epoch_date=setup_date(c, args.epoch, setup), visit=visit_overview(plans, summaries))
    print(f"wrote {path}: {len(plan.rois)} windows, {plan.total_seconds / 60:.1f} min "
          f"(budget {plan.budget_seconds / 60:.0f} min) on a {plan.profile.name}")
    return 0


EXIT_SHORT = 3


def _pair(advice, layout, asked: bool, sigma_mm: float | None = None, first=None):
    """The proposed pair of set-ups, when asked or when the first station (default: the best single one) cannot
    measure a deck target (hidden, weak, or above the sigma asked)."""
    best = first or next((s for s in advice.stations if s.predicted_sigma_mm), None)
    if not asked and (best is None or not short_of(best, layout, sigma_mm)):
        return None
    return propose_pair(advice.stations, layout, sigma_mm=sigma_mm, first=first)


def _three(advice, layout, asked: bool, sigma_mm: float | None, first, pair):
    """Three set-ups, when a second one was asked or needed and no pair measures every deck target (to the sigma
    asked): kept only when they leave fewer deck targets short than the best pair."""
    best = first or next((s for s in advice.stations if s.predicted_sigma_mm), None)
    if not asked and (best is None or not short_of(best, layout, sigma_mm)):
        return None
    if pair is not None and not above(pair, sigma_mm):
        return None
    three = propose_three(advice.stations, layout, first=first, sigma_mm=sigma_mm)
    if three is not None and pair is not None and len(above(three, sigma_mm)) >= len(above(pair, sigma_mm)):
        three = None
    if three is None and pair is None and asked:
        print("no second station shares three targets seen well from both with the first one, and no third station "
              "joins them: no pair or three to propose", file=sys.stderr)
    return three


def _whole_visit(c, label: str) -> bool:
    """Whether the visit has several set-ups and every one of them its fine scans (its check is then the visit's)."""
    setups = [k for k in c.setups(label) if c.files(label, "coarse", setup=k)]
    return len(setups) > 1 and all(c.files(label, "fine", setup=k) for k in setups)


def cmd_check(args) -> int:
    with open_campaign(args.dir) as c:
        c.epoch(args.epoch)
        setup = setup_of(c, args)
        with progress_bar("measuring the fine scans") as cb:
            if _whole_visit(c, args.epoch):
                visit = check_visit(c, args.epoch, goal_sigma_mm=args.goal_mm, progress=cb)
                result = visit.setups[setup]
            else:
                visit, result = None, check_epoch(c, args.epoch, goal_sigma_mm=args.goal_mm, setup=setup, progress=cb)
    if args.out is not None and result.rescan is not None:
        result.rescan.save(args.out)
    if visit is not None:
        return _visit_check_out(args, visit, setup)
    if args.json:
        dump_json(result.to_json())
    else:
        table([t.to_json() for t in result.targets],
              ["reflector", "group", "status", "points", "planned_points", "points_ratio", "sigma_mm", "goal_sigma_mm",
               "note"])
        cl = result.closure
        if cl is not None and cl.status == "not measured":
            print(f"closure ({cl.reflector}): not measured; {cl.note}")
        elif cl is not None:
            print(f"closure ({cl.reflector}): the set-up turned {cl.angle_arcsec:.1f}\" +- {cl.sigma_arcsec:.1f}\" in "
                  f"{cl.minutes:.0f} min ({'within' if cl.status == 'ok' else 'BEYOND'} the instrument's "
                  f"{cl.tolerance_arcsec:g}\"){'; ' + cl.note if cl.note else ''}")
        if not result.short and (cl is None or cl.status != "drifted"):
            print(f"epoch {args.epoch}: every target is good; the visit is complete")
        else:
            names = ", ".join(t.reflector for t in result.short)
            where = f"wrote the re-scan plan {args.out}" if args.out else "give --out FILE for a re-scan plan"
            minutes = f" ({result.rescan.total_seconds / 60:.1f} min)" if result.rescan is not None else ""
            print(f"epoch {args.epoch}: re-scan {names or 'the drifted set-up'} before leaving{minutes}; {where}")
    drifted = result.closure is not None and result.closure.status == "drifted"
    return 0 if not result.short and not drifted else EXIT_SHORT


def _visit_check_out(args, visit, setup: int) -> int:
    """The check of a whole visit: set-up ``setup``'s rows, then the visit's one verdict (exit 3 when it asks)."""
    result = visit.setups[setup]
    if args.json:
        dump_json({**result.to_json(), "setup": setup, "visit": visit.to_json()})
        return 0 if visit.ok else EXIT_SHORT
    table([t.to_json() for t in result.targets],
          ["reflector", "group", "status", "points", "planned_points", "points_ratio", "sigma_mm", "goal_sigma_mm",
           "note"])
    for t, k in sorted(visit.covered.items()):
        print(f"{t}: short from set-up {next(j for j, ch in visit.setups.items() if t in {x.reflector for x in ch.short})}"
              f", measured well by set-up {k}: no re-scan")
    for k in visit.drifted:
        cl = visit.setups[k].closure
        print(f"set-up {k}: closure ({cl.reflector}) turned {cl.angle_arcsec:.1f}\" in {cl.minutes:.0f} min; {cl.note}")
    setups = ", ".join(map(str, sorted(visit.setups)))
    if visit.ok:
        print(f"epoch {args.epoch} (set-ups {setups}): every target is measured well by one set-up or another; "
              "the visit is complete")
        return 0
    for k, why in sorted(visit.rescan.items()):
        if not why:
            continue
        plan = visit.setups[k].rescan
        where = (f"wrote the re-scan plan {args.out}" if args.out and k == setup else
                 f"'bridgesurvey check {args.dir} --epoch {args.epoch} --setup {k} --out FILE' writes its plan")
        minutes = f" ({plan.total_seconds / 60:.1f} min)" if plan is not None else ""
        print(f"epoch {args.epoch}: re-scan from set-up {k}: " + "; ".join(f"{t} ({w})" for t, w in sorted(why.items()))
              + f"{minutes}; {where}")
    return EXIT_SHORT


def _first_xy(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--first expects x,y in metres (layout frame), got {text!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"--first expects finite x,y in metres, got {text!r}")
    return (x, y)


def cmd_stations(args) -> int:
    area = read_area_csv(args.area) if args.area is not None else None
    if args.top < 0:
        raise InputError("--top must not be negative")
    if args.sigma_mm is not None and not (math.isfinite(args.sigma_mm) and args.sigma_mm > 0):
        raise InputError(f"--sigma-mm must be a positive number of millimetres, got {args.sigma_mm}")
    first_xy = _first_xy(args.first)
    with open_campaign(args.dir, writable=False) as c:
        with progress_bar("evaluating stations") as cb:
            advice = advise_stations(c, area_xy=area, height_m=args.height_m, grid_m=args.grid_m,
                                     ground_z=args.ground_z, also_xy=first_xy, progress=cb)
        layout = c.layout()
        first = None
        if first_xy is not None:
            first = min(advice.stations, key=lambda s: math.hypot(s.xyz_layout[0] - first_xy[0],
                                                                  s.xyz_layout[1] - first_xy[1]))
            if not first.predicted_sigma_mm:
                raise InputError(f"--first {args.first}: no deck target can be measured from there "
                                 f"({', '.join(sorted(set(first.reasons.values()))) or 'nothing seen'})")
        pair = _pair(advice, layout, args.pair, args.sigma_mm, first)
        three = _three(advice, layout, args.pair, args.sigma_mm, first, pair)
        positions = [] if pair is None else [pair.first.xyz_layout, pair.second.xyz_layout]
        if three is not None:  # three set-ups do better than any pair: the visit is theirs
            positions = [s.xyz_layout for s in three.stations]
        visit = None
        if positions:  # the visit planned together from the two (three) positions
            try:
                visit = plan_from_positions(c, positions)
            except SurveyError as exc:
                print(f"the {'three set-ups' if three else 'pair'}'s visit cannot be planned together: "
                      f"{str(exc).splitlines()[0]}", file=sys.stderr)
    best = first or next((s for s in advice.stations if s.predicted_sigma_mm), None)
    short = short_of(best, layout, args.sigma_mm) if best is not None else {}
    extra = {"sigma_asked_mm": args.sigma_mm, "best_cannot": short} if short or args.sigma_mm is not None else {}
    if first is not None:
        extra = {**extra, "first": first.to_json()}
    if pair is None and three is None and not extra:
        advice.save(args.out)
    else:
        pair_doc = {}
        for key, got in (("pair", pair), ("three", three)):
            if got is not None:  # the visit planned from the positions goes with the one proposed
                mine = visit if (key == "three") == (three is not None) else None
                pair_doc[key] = dict(got.to_json(), still_short=list(above(got, args.sigma_mm)),
                                     visit=None if mine is None else positions_visit_json(mine, positions))
        write_atomic(args.out, json.dumps({**advice.to_json(), **extra, **pair_doc}, indent=1))
    if args.png is not None:
        save_figure(station_map_figure(advice, layout), args.png)
    rows = [{"x": s.xyz_layout[0], "y": s.xyz_layout[1], "z": s.xyz_layout[2], "minutes": s.seconds / 60,
             "worst_sigma_mm": s.worst_sigma_mm, "coarse_step_deg": s.coarse_step_deg, "hidden": list(s.hidden),
             "weak": list(s.weak)} for s in advice.stations[:args.top]]
    table(rows, ["x", "y", "z", "minutes", "worst_sigma_mm", "coarse_step_deg", "hidden", "weak"])
    if best is not None and short:
        asked = f" to {args.sigma_mm:g} mm" if args.sigma_mm is not None else ""
        print(f"from {'the first station' if first else 'the best single station'} "
              f"({best.xyz_layout[0]:.1f}, {best.xyz_layout[1]:.1f}) "
              f"{len(short)} deck target(s) cannot be measured{asked}: "
              + "; ".join(f"{t} ({why})" for t, why in short.items()))
    if pair is not None and short:
        b = pair.second.xyz_layout
        left = above(pair, args.sigma_mm)
        print(f"a second set-up at ({b[0]:.1f}, {b[1]:.1f}) measures "
              + (f"all of them{' to ' + format(args.sigma_mm, 'g') + ' mm' if args.sigma_mm else ''}" if not left else
                 f"all but {', '.join(left)}"))
    if pair is not None:
        a, b = pair.first.xyz_layout, pair.second.xyz_layout
        worst = "-" if math.isinf(pair.worst_sigma_mm) else f"{pair.worst_sigma_mm:.3f}"
        print(f"two set-ups: ({a[0]:.1f}, {a[1]:.1f}) and ({b[0]:.1f}, {b[1]:.1f}), worst target's sigma "
              f"{worst} mm (one set-up: {pair.first.worst_sigma_mm:.3f} mm), "
              f"{len(pair.shared)} targets shared to join them"
              + (f"; still hidden: {', '.join(pair.hidden)}" if pair.hidden else ""))
    if three is not None:
        where = ", ".join(f"({s.xyz_layout[0]:.1f}, {s.xyz_layout[1]:.1f})" for s in three.stations)
        left = above(three, args.sigma_mm)
        worst = "-" if math.isinf(three.worst_sigma_mm) else f"{three.worst_sigma_mm:.3f}"
        why = "measures every deck target" if pair else "can be joined to the first one"
        print(f"no second set-up {why} (a pair must share three targets seen well from both, spread off a line): "
              f"three set-ups at {where}, each joined to those before it by "
              f"{', '.join(str(len(s)) for s in three.shared)} targets, measure "
              + ("every deck target" if not left else f"all but {', '.join(left)}")
              + f"; worst target's sigma {worst} mm")
    if visit is not None:  # the visit planned together from the two positions, before any coarse scan
        for row in positions_visit_json(visit, positions)["setups"]:
            deck = row["deck_targets_assigned"]
            print(f"  set-up {row['setup']} at ({row['x']:.1f}, {row['y']:.1f}): {len(row['targets'])} windows, "
                  f"{row['minutes']:.0f} min; deck targets {', '.join(deck) or 'none'}"
                  + (f"; ties {', '.join(row['ties'])}" if row["ties"] else ""))
        for w in visit.warnings:
            print(f"  {w}")
    print(f"wrote {args.out}: {len(advice.stations)} stations evaluated (ground z {advice.ground_z:.2f} m: "
          f"{advice.ground_source})" + (f"; map {args.png}" if args.png else ""), file=sys.stderr)
    return 0

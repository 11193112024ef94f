"""Long and multi-span bridges (issue 28): one and two set-ups a visit, stations at the ends and in the middle.

Our own simulation, the product's whole chain (``projects.studies.run_study``): bridges of 1 to 4 spans (20-60 m
each; the multi-span layout: two targets on each end pier, one on each face of an inner pier, six deck targets
a span), every visit's coarse scan imported as a surveyor would (``add-epoch``, ``add-setup`` for a second
station), each set-up planned by the product, its fine windows simulated and imported, then processed.
Riegl VZ-1000 profile, 1000 points a target, the instrument 1.5 m above the ground 6-10 m beside the deck,
somewhere new each visit (a few metres along the bridge, any heading); every visit has its own span
displacements (0 to -8 mm). The surveyor gives set-up 1's rough place (``settings station_xy``): the layout is
symmetric, and a station that sees it symmetrically is otherwise refused as ambiguous.

Stations (x along the bridge of length L):

* one, end - one set-up 0.1 L from the first pier;
* one, middle - one set-up beside midspan;
* one, inner pier - one set-up beside the first inner pier of a three-span bridge (a third of the way along);
* two, ends - two set-ups, 0.28 L from each end (in the end spans of a three-span bridge);
* two, end + middle - one at 0.1 L, one beside midspan.

Columns: displacement error against the truth over every deck target and visit after the baseline (RMS and
max, mm), the share of errors within 2 sigma, the share beyond 3 sigma WITHOUT a warning or problem flag on
their own row (must be 0), the same for the along-span movements (must be 0), and the deck targets measured /
expected.

``--together`` (issue 40): the two-set-up stations only, each visit's coarse scans taken first and its set-ups
planned alone (each as if it were the visit's only one, ``plan_together false``, as before) and together (each
target from the set-up that measures it best, tie targets, the visit's budget shared), from the same scans, in the
same total time: planned alone each set-up has ``budget_min`` (60 min), planned together the visit has
``budget_min`` a set-up (the default ``visit_budget_min``); the table goes to
``docs/figures/long_bridges_together.md``. Its columns add the share beyond 3 sigma without a flag and the mean
planned fine-scan minutes a visit; ``--visit-budget-min M`` adds the set-ups planned together in a visit of M
minutes (a visit too short for the points asked: the plan says so).

Usage: ``./run bench long_bridges [--visits N] [--quick] [--seed S] [--together] [--bridges 2,3]`` (about 1 min a set-up visit of a long bridge
on a loaded two-core machine; ``--quick``: the three-span bridge only; ``--small``: a short two-span bridge, two
set-ups a visit planned alone and together, 2 visits, coarse scans at 0.1 degrees, in about two minutes).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _harness import SMALL, figures, write_figure

from lidar.simulate.bridge import BridgeModel
from lidar.simulate.scene import EpochConditions
from lidar.simulate.setup import ScannerSetup
from projects.store.campaign import Campaign
from projects.studies import StudyScore, run_study

BRIDGES = {
    "1 x 60 m": (60.0,),
    "2 x 40 m": (40.0, 40.0),
    "3 x 39.9 m": (39.9, 39.9, 39.9),
    "4 spans 20-30 m": (20.0, 30.0, 30.0, 20.0),
}
STATIONS = {
    "one, end": (0.1,),
    "one, middle": (0.5,),
    "one, inner pier": (1.0 / 3.0,),
    "two, ends": (0.28, 0.72),
    "two, end + middle": (0.1, 0.5),
}
#: ``--unlike``: bridges further from the demo (five spans; a shallow, wide deck on two girder lines as a steel
#: plate-girder deck has, its targets on both girder lines), each with extra BridgeModel settings.
UNLIKE = {
    "5 x 30 m, concrete box": ((30.0,) * 5, {}),
    "4 x 35 m, steel: deck 1.2 m deep, 10 m wide, girder lines ±3.5 m": (
        (35.0,) * 4, {"deck_depth_m": 1.2, "deck_width_m": 10.0, "girder_lines_m": (-3.5, 3.5)}),
}
#: ``--unlike``'s station plans: near the ends, beside the first and the last inner pier (``None``: from the
#: spans), and three set-ups (near the ends and beside the middle; not at it: a station that sees the symmetric
#: layout symmetrically is refused as ambiguous unless the surveyor says where it stands).
UNLIKE_STATIONS = {
    "two, near the ends": (0.1, 0.9),
    "two, beside the first and last inner piers": None,
    "three, near the ends and beside the middle": (0.1, 0.45, 0.9),
}
#: The small mode's bridge and stations: the multi-span layout and two set-ups a visit, on a short bridge.
SMALL_BRIDGES = {"2 x 15 m": (15.0, 15.0)}
SMALL_STATIONS = {"two, ends": (0.28, 0.72)}
OUT = Path(__file__).resolve().parent / "out"


def _multi(spans: tuple, **model_kw) -> BridgeModel:
    """The multi-span layout for every bridge (also one span: six deck targets on two girder lines)."""
    return BridgeModel(spans_m=spans, deck_fractions=(0.4, 0.5, 0.6), **model_kw)


def inner_pier_fractions(spans: tuple) -> tuple[float, float]:
    """The first and the last inner pier, as fractions of the bridge's length."""
    edges = np.cumsum(spans) / sum(spans)
    return (float(edges[0]), float(edges[-2]))


def _stations(model: BridgeModel, fractions: tuple, rng: np.random.Generator) -> list[ScannerSetup]:
    length = model.length_m
    return [ScannerSetup((f * length + rng.uniform(-2.0, 2.0), -(model.deck_width_m / 2 + rng.uniform(6.0, 10.0)),
                          rng.uniform(1.4, 1.6)), heading_deg=float(rng.uniform(0.0, 360.0))) for f in fractions]


def scenario(root: Path, spans: tuple, fractions: tuple, *, visits: int, seed: int,
             coarse_step_deg: float = 0.05, together: bool | None = None,
             budget_min: float | None = None, model_kw: dict | None = None,
             visit_budget_min: float | None = None) -> StudyScore:
    """One bridge and station plan: simulate, import, process, score.

    ``together`` None: each set-up planned and fine-scanned before the next one's coarse scan, as on site, with the
    campaign's default planning (together since issue 40: a set-up's plan frozen once its fine scans are in; the
    table in docs/figures/long_bridges.md was measured before, each set-up alone); True / False: every coarse scan
    of a visit first, then its set-ups planned together / alone.
    """
    model = _multi(spans, **(model_kw or {}))
    rng = np.random.default_rng(seed)
    conditions = [EpochConditions()] + [EpochConditions(span_displacements_m=tuple(
        float(v) for v in rng.uniform(-0.008, 0.0, model.n_spans))) for _ in range(visits - 1)]
    stations = [_stations(model, fractions, rng) for _ in conditions]
    # the surveyor says roughly where set-up 1 stands (a symmetric bridge is otherwise refused as ambiguous)
    hint = f"{fractions[0] * model.length_m:.1f},{-(model.deck_width_m / 2 + 8.0):.1f}"
    settings = {"station_xy": hint} if together is None else {"station_xy": hint, "plan_together": together}
    if budget_min is not None:
        settings["budget_min"] = budget_min
    if visit_budget_min is not None:
        settings["visit_budget_min"] = visit_budget_min
    return run_study(root, model, conditions, stations=stations, seed=seed, settings=settings,
                     coarse_step_deg=coarse_step_deg, coarse_first=together is not None)["corrected"]


def planned_minutes(root: Path) -> float:
    """Mean planned fine-scan minutes a visit (every set-up's plan) of a scenario's campaign."""
    with Campaign.open(root / "campaign", writable=False) as c:
        totals = [sum(p.total_seconds for p in (c.plan(e.label, k) for k in c.setups(e.label)) if p is not None)
                  for e in c.epochs()]
    return float(np.mean(totals)) / 60.0 if totals else float("nan")


def sigma_rms(s: StudyScore) -> float:
    """RMS of the displacements' own sigmas, mm: what the plans gave, without the luck of a few dozen errors."""
    v = np.asarray(s.sigmas_mm, dtype=float)
    return float(np.sqrt(np.mean(v ** 2))) if v.size else float("nan")


def together_table(rows: dict) -> str:
    lines = ["| bridge | stations | set-ups planned | deck targets measured | RMS mm | max mm | σ mm (RMS) "
             "| beyond 3σ without a flag | fine scans min a visit |", "|---|---|---|---|---|---|---|---|---|"]
    for (bridge, stations, how), (s, minutes) in rows.items():
        r = s.row()
        lines.append(f"| {bridge} | {stations} | {how} | {r['measured']} | {r['rms_mm']:.3f} | {r['max_mm']:.3f} | "
                     f"{sigma_rms(s):.3f} | {r['silent_beyond_3sigma']:.1%} | {minutes:.0f} |")
    return "\n".join(lines)


def table(rows: dict) -> str:
    lines = ["| bridge | stations | RMS mm | max mm | within 2σ | beyond 3σ without a flag | along-span: beyond 3σ "
             "without a flag | deck targets measured |", "|---|---|---|---|---|---|---|---|"]
    for (bridge, stations), s in rows.items():
        r = s.row()
        lines.append(f"| {bridge} | {stations} | {r['rms_mm']:.3f} | {r['max_mm']:.3f} | {r['within_2sigma']:.0%} | "
                     f"{r['silent_beyond_3sigma']:.1%} | {r['along_silent_beyond_3sigma']:.1%} | {r['measured']} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--visits", type=int, default=3)
    ap.add_argument("--seed", type=int, default=28)
    ap.add_argument("--quick", action="store_true", help="the three-span bridge only")
    ap.add_argument(SMALL, action="store_true", help="a short two-span bridge, two set-ups, 2 visits (seconds)")
    ap.add_argument("--together", action="store_true",
                    help="the two-set-up stations, their set-ups planned alone and together (issue 40)")
    ap.add_argument("--bridges", default="", help="the bridges by their number of spans, e.g. 2,3 (default all)")
    ap.add_argument("--visit-budget-min", type=float, default=None,
                    help="also plan together in a visit of this many minutes (visit_budget_min)")
    ap.add_argument("--budget-min", type=float, default=None,
                    help="a set-up's fine-scan budget, minutes (default the campaign's, 60)")
    ap.add_argument("--unlike", action="store_true",
                    help="bridges unlike the demo (five spans; a steel deck on girder lines), two set-ups near the "
                         "ends and beside the inner piers, planned alone and together")
    args = ap.parse_args()
    if args.unlike and not args.small:
        unlike(args)
        return
    if args.together or args.small:
        together(args)
        return
    print(__doc__.split("Usage")[0].strip() + "\n")
    OUT.mkdir(exist_ok=True)
    bridges = {k: v for k, v in BRIDGES.items() if not args.quick or k.startswith("3")}
    stations = STATIONS
    if args.small:
        bridges, stations = SMALL_BRIDGES, SMALL_STATIONS
        args.visits = min(args.visits, 2)
    rows: dict = {}
    silent = 0.0
    for n, (bridge, spans) in enumerate(bridges.items()):
        for m, (name, fractions) in enumerate(stations.items()):
            t0 = time.perf_counter()
            s = scenario(OUT / ("long_bridges_small" if args.small else "long_bridges") / f"b{n}s{m}", spans,
                         fractions, visits=args.visits, seed=args.seed + 10 * n + m,
                         coarse_step_deg=0.1 if args.small else 0.05)
            rows[(bridge, name)] = s
            silent = max(silent, s.silent_beyond_3sigma if s.errors_mm else 0.0,
                         s.along_silent_beyond_3sigma if s.along_errors_mm else 0.0)
            print(f"{bridge}, {name}: {s.row()} ({time.perf_counter() - t0:.0f} s)", flush=True)
    print()
    print(table(rows))
    if not args.small:
        (OUT / "long_bridges.json").write_text(json.dumps({f"{b} | {s}": v.row() for (b, s), v in rows.items()},
                                                          indent=1))
    print(f"\nlargest share beyond 3 sigma without a flag: {silent:.1%} (must be 0)")
    if not args.quick and not args.small:  # one bridge is no table for the documentation
        write_figure("long_bridges", table(rows))
    scores = list(rows.values())
    figures(scenarios=len(rows), visits=args.visits, displacements=sum(len(s.errors_mm) for s in scores),
            missing=sum(s.missing for s in scores), expected=sum(s.expected for s in scores),
            rms_mm_max=float(np.nanmax([s.rms_mm for s in scores])), silent_beyond_3sigma_max=silent)


def together(args) -> None:
    """The two-set-up stations with their set-ups planned alone and together, from the same scans (issue 40)."""
    print(__doc__.split("Usage")[0].strip() + "\n")
    OUT.mkdir(exist_ok=True)
    wanted = {int(v) for v in args.bridges.split(",") if v.strip()}
    bridges = SMALL_BRIDGES if args.small else {k: v for k, v in BRIDGES.items() if not wanted or len(v) in wanted}
    stations = SMALL_STATIONS if args.small else {k: v for k, v in STATIONS.items() if len(v) == 2}
    visits = min(args.visits, 2) if args.small else args.visits
    rows: dict = {}
    for n, (bridge, spans) in enumerate(BRIDGES.items() if not args.small else bridges.items()):
        if bridge not in bridges:
            continue
        for m, (name, fractions) in enumerate(STATIONS.items() if not args.small else stations.items()):
            if name not in stations:
                continue
            modes = [("alone", False, None), ("together", True, None)]
            if args.visit_budget_min is not None:
                modes.append((f"together, in a visit of {args.visit_budget_min:g} min", True, args.visit_budget_min))
            for how, flag, visit_min in modes:
                t0 = time.perf_counter()
                root = OUT / ("long_bridges_small" if args.small else "long_bridges_together") / \
                    f"b{n}s{m}{how[0]}{'v' if visit_min else ''}"
                s = scenario(root, spans, fractions, visits=visits, seed=args.seed + 10 * n + m,
                             coarse_step_deg=0.1 if args.small else 0.05, together=flag, budget_min=args.budget_min,
                             visit_budget_min=visit_min)
                rows[(bridge, name, how)] = (s, planned_minutes(root))
                print(f"{bridge}, {name}, planned {how}: {s.row()} ({time.perf_counter() - t0:.0f} s)", flush=True)
    print()
    print(together_table(rows))
    if not args.small:
        (OUT / f"long_bridges_together{'' if args.budget_min is None else int(args.budget_min)}.json").write_text(json.dumps(
            {f"{b} | {s} | {h}": dict(v.row(), minutes=mins, sigma_rms_mm=sigma_rms(v))
             for (b, s, h), (v, mins) in rows.items()}, indent=1))
        if args.budget_min is None:  # the documentation's table is the campaign's default budget
            write_figure("long_bridges_together", together_table(rows))
    scores = [s for s, _ in rows.values()]
    silent = max((s.silent_beyond_3sigma for s in scores if s.errors_mm), default=0.0)
    alone = [s for (_, _, h), (s, _) in rows.items() if h == "alone"]
    joint = [s for (_, _, h), (s, _) in rows.items() if h == "together"]
    figures(scenarios=len(alone), visits=visits, displacements=sum(len(s.errors_mm) for s in scores),
            missing=sum(s.missing for s in scores), expected=sum(s.expected for s in scores),
            rms_mm_max=float(np.nanmax([s.rms_mm for s in scores])), silent_beyond_3sigma_max=silent,
            missing_alone=sum(s.missing for s in alone), missing_together=sum(s.missing for s in joint))


def unlike(args) -> None:
    """Bridges unlike the demo, two set-ups a visit, planned alone and together from the same scans (issue 40)."""
    print(__doc__.split("Usage")[0].strip() + "\n")
    OUT.mkdir(exist_ok=True)
    rows: dict = {}
    for n, (bridge, (spans, kw)) in enumerate(UNLIKE.items()):
        for m, (name, fractions) in enumerate(UNLIKE_STATIONS.items()):
            fr = fractions if fractions is not None else inner_pier_fractions(spans)
            for how, flag in (("alone", False), ("together", True)):
                t0 = time.perf_counter()
                root = OUT / "long_bridges_unlike" / f"b{n}s{m}{how[0]}"
                s = scenario(root, spans, fr, visits=args.visits, seed=args.seed + 100 + 10 * n + m,
                             together=flag, budget_min=args.budget_min, model_kw=kw)
                rows[(bridge, f"{name} ({', '.join(f'{f * sum(spans):.0f}' for f in fr)} m)", how)] = (
                    s, planned_minutes(root))
                print(f"{bridge}, {name}, planned {how}: {s.row()} ({time.perf_counter() - t0:.0f} s)", flush=True)
    print()
    print(together_table(rows))
    (OUT / "long_bridges_unlike.json").write_text(json.dumps(
        {f"{b} | {s} | {h}": dict(v.row(), minutes=mins, sigma_rms_mm=sigma_rms(v))
         for (b, s, h), (v, mins) in rows.items()}, indent=1))
    write_figure("long_bridges_unlike", together_table(rows))
    scores = [s for s, _ in rows.values()]
    figures(scenarios=len(rows), visits=args.visits, displacements=sum(len(s.errors_mm) for s in scores),
            missing=sum(s.missing for s in scores), expected=sum(s.expected for s in scores),
            rms_mm_max=float(np.nanmax([s.rms_mm for s in scores])),
            silent_beyond_3sigma_max=max((s.silent_beyond_3sigma for s in scores if s.errors_mm), default=0.0))


if __name__ == "__main__":
    main()

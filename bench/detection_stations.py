"""Coarse detection from any station, under three intensity models (issue 39, item 4).

Full ray-cast coarse scans of two bridges (the demo's 40 m one with 5 deck targets, a 60 m one with a 10 m deck
and 8), the scanner levelled near midspan (0.42-0.58 of the span) at 5, 6, 7 and 15 m beside the deck's edge,
a new heading and spot every visit (two visits each; ``--visits N``). Each scan is made under each intensity model of the simulator
(:class:`lidar.simulate.effects.IntensityModel`): ``mild`` (the simulator's first model), ``amplitude`` (raw
amplitude as reflectance x cos(incidence) x (r0/r)^2 with a receiver ceiling: targets and close concrete clip)
and ``db`` (the same on a logarithmic scale). The product's coarse analysis
(:func:`lidar.pipeline.analyse_coarse`: detection, identification against a layout with 2 cm errors, the guided
look) then counts the deck (measurement) targets found blind by the blob search and after the guided look, and
the reference targets found.

Printed: one row per model and station distance, deck targets found blind / after the guided look / in view,
the pier targets found, false detections, and the one-line notes the analysis gives for targets still missing.

Usage: ``./run bench detection_stations`` (about 10 minutes on two cores; ``--small``: the 40 m bridge, one visit
at 6 m and one at 15 m, each model).
"""
from __future__ import annotations

import sys

import numpy as np
from _harness import figures, small_mode, write_figure

from lidar.layout import layout_from_model
from lidar.pipeline import analyse_coarse
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.bridge import Target
from lidar.simulate.effects import INTENSITY_KINDS, IntensityModel

STEP_DEG = 0.05
DISTANCES_M = (5.0, 6.0, 7.0, 15.0)


def _wide_bridge() -> BridgeModel:
    span, width, bottom = 60.0, 10.0, 9.0
    face1, face2 = 1.001, span - 1.001
    refs = [Target("R1", "reference", (face1, -4.0, 2.0), (1, 0, 0)),
            Target("R2", "reference", (face1, 4.0, 0.7 * bottom), (1, 0, 0)),
            Target("R3", "reference", (face2, 4.0, 2.0), (-1, 0, 0)),
            Target("R4", "reference", (face2, -4.0, 0.7 * bottom), (-1, 0, 0))]
    lines = (-4.0, 0.0, 4.0)
    deck = [Target(f"M{k + 1}", "measurement", (f * span, lines[k % 3], bottom - 0.001), (0, 0, -1))
            for k, f in enumerate((0.15, 0.27, 0.38, 0.5, 0.62, 0.73, 0.85, 0.44))]
    return BridgeModel(span_m=span, deck_width_m=width, deck_bottom_m=bottom, pier_width_m=9.0,
                       targets=tuple(refs + deck))


BRIDGES = {"40 m / 6 m deck": BridgeModel(), "60 m / 10 m deck": _wide_bridge()}


def station(model: BridgeModel, distance_m: float, rng: np.random.Generator) -> ScannerSetup:
    """A levelled set-up near midspan, ``distance_m`` beside the deck's edge, on either side."""
    side = rng.choice((-1.0, 1.0))
    return ScannerSetup((rng.uniform(0.42, 0.58) * model.span_m, side * (model.deck_width_m / 2 + distance_m),
                         rng.uniform(1.2, 1.8)), heading_deg=rng.uniform(0, 360),
                        pitch_deg=rng.normal(0, 0.02), roll_deg=rng.normal(0, 0.02))


def count(model: BridgeModel, setup: ScannerSetup, kind: str, seed: int) -> dict:
    """One coarse scan under one intensity model through the product's coarse analysis; what it found."""
    layout = layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(seed))
    scene = BridgeScene(model, EpochConditions(intensity_model=IntensityModel(kind)), setup)
    coarse, truth = scene.scan(scene.coarse_window(STEP_DEG), rng=np.random.default_rng(seed))
    deck = {t.id for t in model.targets if t.group == "measurement"}
    refs = {t.id for t in model.targets if t.group == "reference"}
    try:
        a = analyse_coarse(coarse, layout)
    except Exception as exc:  # the analysis refused the scan: nothing found, and why
        return {"blind": 0, "guided": 0, "refs": 0, "false": 0, "deck": len(deck), "notes": [str(exc)[:200]]}
    dets = a.detections.detections
    found = {m.id: dets[m.detection] for m in a.identification.matches if m.detection is not None}
    # a detection counts when it lies within 10 cm of the truth (identification may be wrong)
    true = {t.id: np.asarray(t.centre_socs_m) for t in truth.targets}
    ok = {i: d for i, d in found.items() if np.linalg.norm(np.asarray(d.xyz_socs) - true[i]) < 0.10}
    blind = sum(1 for i, d in ok.items() if i in deck and not d.guided)
    guided = sum(1 for i in ok if i in deck)
    notes = [a.missing_note] if a.missing_note else []
    return {"blind": blind, "guided": guided, "refs": sum(1 for i in ok if i in refs),
            "false": len(found) - len(ok), "deck": len(deck), "notes": notes}


def main() -> None:
    small, args = small_mode()
    bridges = dict(list(BRIDGES.items())[:1]) if small else BRIDGES
    distances = (6.0, 15.0) if small else DISTANCES_M
    visits = 1 if small else int(args[args.index("--visits") + 1]) if "--visits" in args else 2
    rows = []
    totals: dict[tuple[str, bool], list[int]] = {}
    for bname, model in bridges.items():
        for dist in distances:
            rng = np.random.default_rng(int(dist * 10) + 7 * len(bname))
            setups = [station(model, dist, rng) for _ in range(visits)]
            for kind in INTENSITY_KINDS:
                res = [count(model, s, kind, 100 + k) for k, s in enumerate(setups)]
                blind = sum(r["blind"] for r in res)
                guided = sum(r["guided"] for r in res)
                n = sum(r["deck"] for r in res)
                refs = sum(r["refs"] for r in res)
                false = sum(r["false"] for r in res)
                key = (kind, dist < 10)
                t = totals.setdefault(key, [0, 0, 0])
                t[0] += blind
                t[1] += guided
                t[2] += n
                notes = sorted({x for r in res for x in r["notes"]})
                rows.append(f"| {bname} | {dist:.0f} m | {kind} | {blind} / {n} | {guided} / {n} | "
                            f"{refs} / {4 * visits} | {false} | {'; '.join(notes)[:300]} |")
                print(rows[-1], flush=True)
    table = ("| bridge | beside the deck | intensity model | deck targets blind | after the guided look | "
             "pier targets | wrong | notes |\n|---|---|---|---|---|---|---|---|\n" + "\n".join(rows))
    print(table)

    def share(kind: str, close: bool, k: int) -> float:
        t = totals.get((kind, close))
        return float("nan") if not t or not t[2] else t[k] / t[2]

    figures(**{f"{kind}_{where}_{what}": share(kind, close, k)
               for kind in INTENSITY_KINDS for where, close in (("close", True), ("far", False))
               for what, k in (("blind", 0), ("guided", 1))})
    write_figure("detection_stations", table, argv=sys.argv[1:])


if __name__ == "__main__":
    main()

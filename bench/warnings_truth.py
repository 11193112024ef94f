"""Warnings measured against the truth (issue 38): do the visits that need action warn, and only those?

Simulated campaigns unlike the demo, with the field physics on (atmosphere, range walk of more than one form,
clipped or saturated intensities, drift, the deck expanding, trains crossing during deck windows) and a few
visits carrying a *trap*: something the surveyor must act on (a cable tie beside a target, a target hidden
or fallen off, a reference target moved). Each campaign is planned, imported and processed as a surveyor
would (:func:`projects.studies.run_study`), then every visit after the baseline is classed by what the
simulator put in it and by the state the product gave it:

* **clean visits that warn**: visits with no trap in a *warning* or *problem* state (a warning the surveyor
  learns to ignore; must be rare, the issue asks for at most 10 %);
* **trapped visits that do not warn**: visits with a trap in neither state (must be none);
* **silent**: displacements off by more than 3 sigma whose row carries no warning (must be none).

Visits with a train crossing and no trap are counted apart: a train the product corrects within sigma is
information, one it cannot correct is a warning, so either state is right as long as nothing is silent.

Usage: ``./run bench warnings_truth [--small]`` (``--small``: one campaign of three visits, the last with a trap).
"""
from __future__ import annotations

import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _harness import figures, small_mode, write_figure  # noqa: E402

from common.flags import PROBLEM, WARNING, severity  # noqa: E402
from lidar.simulate.bridge import BridgeModel  # noqa: E402
from lidar.simulate.campaign import random_conditions  # noqa: E402
from lidar.simulate.effects import (  # noqa: E402
    DeckTransient,
    InverseSquareWalk,
    LinearIncidenceWalk,
    StrengthStepWalk,
    VisitTiming,
)
from lidar.simulate.scene import EpochConditions  # noqa: E402
from lidar.simulate.setup import ScannerSetup  # noqa: E402
from projects.results.state import epoch_states  # noqa: E402
from projects.store.campaign import Campaign  # noqa: E402
from projects.studies import StudyScore, run_study  # noqa: E402

#: What a trap does to a visit, by name (the simulator's conditions for one target).
TRAPS = {
    "cable tie": lambda c, t: replace(c, cable_ties=(t,)),
    "occluded": lambda c, t: replace(c, occluded=(t,)),
    "fallen off": lambda c, t: replace(c, removed=(t,)),
    "reference moved 4 mm": lambda c, t: replace(c, moved_targets={t: (0.0, 0.0, -0.004)}),
    "reference moved 3 mm along": lambda c, t: replace(c, moved_targets={t: (0.003, 0.0, 0.0)}),
}


@dataclass(frozen=True)
class Campaign_:
    """One simulated campaign: the bridge, the physics, the stations and the traps by visit index."""

    name: str
    model: BridgeModel
    visits: int
    physics: dict
    traps: dict = field(default_factory=dict)  # visit index -> (trap name, target)
    trains: tuple = ()  # visit indices with a train crossing
    station: str = "beside"  # "beside" (10-20 m off), "close" (6-9 m off), "ends" (two set-ups near the ends)
    seed: int = 0


def _conditions(camp: Campaign_) -> list[EpochConditions]:
    rng = np.random.default_rng(camp.seed)
    p = camp.physics
    out = []
    for k in range(camp.visits):
        c = random_conditions(camp.model, rng, ppm=p.get("ppm", (0, 0)), max_walk_m=None,
                              clipped_fraction=p.get("clip", (0, 0)), temperature_c=p.get("temperature", (0, 0)),
                              drift_arcsec_per_h=p.get("drift", 0.0))
        c = replace(c, range_walk=p.get("walk"), saturated=p.get("saturated", False),
                    timing=VisitTiming(start_s=0.0, gap_s=30.0, duration="lines"))
        if k in camp.trains:  # three crossings of 8-12 s spread over the visit, 2-4 mm down
            c = replace(c, transient=DeckTransient(
                start_s=tuple(float(s) for s in rng.uniform(60.0, 1500.0, 3)),
                duration_s=tuple(float(d) for d in rng.uniform(8.0, 12.0, 3)),
                amplitude_m=tuple(float(a) for a in rng.uniform(-0.004, -0.002, 3)), wobble=0.1))
        if k in camp.traps:
            name, target = camp.traps[k]
            c = TRAPS[name](c, target)
        out.append(c)
    return out


def _stations(camp: Campaign_) -> list[list[ScannerSetup]]:
    rng = np.random.default_rng(camp.seed + 101)
    m = camp.model
    if camp.station == "ends":
        length = m.length_m
        return [[ScannerSetup((f * length + rng.uniform(-2.0, 2.0), -(m.deck_width_m / 2 + rng.uniform(6.0, 10.0)),
                               rng.uniform(1.4, 1.6)), heading_deg=float(rng.uniform(0.0, 360.0)))
                 for f in (0.12, 0.88)] for _ in range(camp.visits)]
    y = (-9.0, -6.0) if camp.station == "close" else (-20.0, -10.0)
    return [[ScannerSetup.random(rng, span_m=m.length_m, y_range_m=y)] for _ in range(camp.visits)]


@dataclass
class WarningScore:
    """Each visit after the baseline by class (clean, train, trap) and state, with the value scores."""

    visits: list = field(default_factory=list)  # (label, class, state, trap or "", summary of warning flags)
    values: StudyScore = field(default_factory=StudyScore)

    def share(self, klass: str, warned: bool) -> tuple[int, int]:
        """(visits of ``klass`` in a warning or problem state (``warned``) or not, visits of ``klass`` processed)."""
        these = [v for v in self.visits if v[1] == klass and v[2] in ("processed", "warning", "problem")]
        return sum((v[2] in ("warning", "problem")) == warned for v in these), len(these)

    @property
    def unprocessed_text(self) -> str:
        """``0``, or ``2 (trap 2)``: the visits refused, by class."""
        left = [v[1] for v in self.visits if v[2] not in ("processed", "warning", "problem")]
        if not left:
            return "0"
        return f"{len(left)} (" + ", ".join(f"{k} {left.count(k)}" for k in ("clean", "train", "trap")
                                           if left.count(k)) + ")"

    @property
    def unprocessed(self) -> int:
        """Visits the product refused to plan or process (each said why when it refused)."""
        return sum(v[2] not in ("processed", "warning", "problem") for v in self.visits)


def run(root: Path, camp: Campaign_, *, coarse_step_deg: float) -> WarningScore:
    conditions = _conditions(camp)
    # the surveyor says roughly where set-up 1 stands, as the product asks for a symmetric layout (two girder lines,
    # three equal spans): the access side, and near which end when the set-ups stand at the ends
    off = {"ends": 8.0, "close": 7.5, "beside": 15.0}[camp.station]
    x = (0.12 if camp.station == "ends" else 0.5) * camp.model.length_m
    settings = {"station_xy": f"{x:.1f},{-(camp.model.deck_width_m / 2 + off):.1f}"}
    values = run_study(root, camp.model, conditions, stations=_stations(camp), seed=camp.seed, settings=settings,
                       coarse_step_deg=coarse_step_deg)["corrected"]
    out = WarningScore(values=values)
    with Campaign.open(root / "campaign", writable=False) as c:
        states = epoch_states(c)
        base = c.settings().get("baseline")
        for k, e in enumerate(c.epochs()):
            if e.label == base:
                continue
            klass = "trap" if k in camp.traps else "train" if k in camp.trains else "clean"
            s = states[e.label]
            loud = "; ".join(f for f in s.flags if severity(f) in (WARNING, PROBLEM)) or values.refused.get(e.label, "")
            out.visits.append((e.label, klass, s.state, " ".join(camp.traps.get(k, ())), loud))
    return out


def campaigns(small: bool) -> list[Campaign_]:
    one = BridgeModel()
    if small:
        return [Campaign_("one span, all effects", one, 3, dict(ppm=(-30, 30), walk=InverseSquareWalk(0.003, 15.0),
                                                                 clip=(0.1, 0.3), temperature=(-15, 15), drift=20.0),
                          traps={2: ("cable tie", "M3")}, seed=11)]
    deep = BridgeModel(deck_depth_m=3.0, deck_bottom_m=8.0, girder_lines_m=(-2.0, 2.0))
    three = BridgeModel(spans_m=(30.0, 30.0, 30.0), deck_fractions=(0.4, 0.5, 0.6))
    return [
        Campaign_("40 m span, atmosphere, walk ∝ 1/range², clipped, drift, deck expanding", one, 8,
                  dict(ppm=(-30, 30), walk=InverseSquareWalk(0.003, 15.0), clip=(0.1, 0.3), temperature=(-15, 15),
                       drift=20.0),
                  traps={2: ("cable tie", "M3"), 4: ("occluded", "M2"), 6: ("reference moved 4 mm", "R2")}, seed=11),
        Campaign_("deep deck on two girder lines, stations 6–9 m beside it, walk linear in cos(incidence), "
                  "saturated, trains", deep, 8,
                  dict(ppm=(-20, 20), walk=LinearIncidenceWalk(0.0015), saturated=True, temperature=(-10, 10)),
                  traps={3: ("fallen off", "M4"), 6: ("cable tie", "R3")}, trains=(2, 5), station="close", seed=12),
        Campaign_("3 × 30 m, two set-ups near the ends, walk a step at a strength threshold, drift", three, 5,
                  dict(ppm=(-20, 20), walk=StrengthStepWalk(0.0015, 0.0002, 0.5), clip=(0.0, 0.2), drift=15.0),
                  traps={3: ("reference moved 3 mm along", "R5")}, station="ends", seed=13),
    ]


def table(rows: dict[str, WarningScore]) -> str:
    lines = ["| campaign | clean visits that warn | trapped visits that do not warn | train visits that warn | "
             "RMS / max mm | beyond 3σ without a flag | visits not processed |", "|---|---|---|---|---|---|---|"]
    for name, s in rows.items():
        cw, cn = s.share("clean", True)
        tq, tn = s.share("trap", False)
        rw, rn = s.share("train", True)
        v = s.values
        lines.append(f"| {name} | {cw} of {cn} | {tq} of {tn} | {f'{rw} of {rn}' if rn else '–'} | "
                     f"{v.rms_mm:.3f} / {v.max_mm:.2f} | {v.silent_beyond_3sigma:.1%} | {s.unprocessed_text} |")
    return "\n".join(lines)


def detail(rows: dict[str, WarningScore]) -> str:
    lines = []
    for name, s in rows.items():
        for label, klass, state, trap, loud in s.visits:
            lines.append(f"  {name[:24]:24s} {label} {klass:5s} {trap:28s} {state:9s} {loud[:110]}")
    return "\n".join(lines)


def main(argv: Sequence[str]) -> int:
    small, argv = small_mode(list(argv))
    rows: dict[str, WarningScore] = {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for k, camp in enumerate(campaigns(small)):
            rows[camp.name] = run(Path(tmp) / f"c{k}", camp, coarse_step_deg=0.05)
            print(f"  {camp.name}: {time.perf_counter() - t0:.0f} s", flush=True)
    print(table(rows))
    print(detail(rows))
    clean = [s.share("clean", True) for s in rows.values()]
    traps = [s.share("trap", False) for s in rows.values()]
    n_clean, n_trap = sum(n for _, n in clean), sum(n for _, n in traps)
    clean_warn = sum(w for w, _ in clean) / n_clean if n_clean else float("nan")
    trap_quiet = sum(q for q, _ in traps) / n_trap if n_trap else float("nan")
    silent = float(np.nanmax([s.values.silent_beyond_3sigma for s in rows.values()]))
    figures(campaigns=len(rows), unprocessed=sum(s.unprocessed for s in rows.values()), clean_visits=n_clean,
            clean_visits_warning=clean_warn, trapped_visits=n_trap,
            trapped_visits_quiet=trap_quiet, silent_beyond_3sigma_max=silent)
    if not small:
        write_figure("warnings_truth", table(rows), argv=list(argv),
                     notes=f"Clean visits in a warning or problem state: {clean_warn:.0%} of {n_clean}; trapped "
                           f"visits without one: {trap_quiet:.0%} of {n_trap}.")
    return 1 if (trap_quiet > 0 or silent > 0) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

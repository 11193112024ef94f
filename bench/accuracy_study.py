"""Accuracy of the reflector method against simulator ground truth (issue 3's figures).

1. The dissertation's lab design: 3 scanner positions x 4 load steps, every case against case 1,
   for several point counts per target.
2. Honesty of the reported sigma over many random epochs: share of |error| / sigma < 2.
3. Traps: a cable tie beside a reference target; a reference target moved by 5 mm.

Usage: ``./run bench accuracy_study [N_EPOCHS]`` (default 40 random epochs); ``--small``: 1000 points a
target only, 2 positions x 2 loads, 4 random epochs and two traps, in seconds.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _harness import figures, small_mode  # noqa: E402

from lidar.displacement import compute_displacements  # noqa: E402
from lidar.simulate import EpochConditions, ScannerSetup  # noqa: E402
from lidar.simulate.epochs import GROUPS, LAB_LOADS_MM, LAB_POSITIONS, fine_epoch  # noqa: E402


def errors(base, base_truth, ep, ep_truth, **kw):
    res = compute_displacements(base, ep, GROUPS, **kw)
    out = []
    for d in res.displacements:
        true = ep_truth.target(d.reflector).vertical_displacement_m - base_truth.target(d.reflector).vertical_displacement_m
        out.append((d.reflector, d.displacement_m - true, d.sigma_m))
    return out, res


def lab_design(min_points: int, seed0: int = 100, mode="reference", *, positions: int = 3, loads: int = 4):
    cases = [(pos, load) for pos in LAB_POSITIONS[:positions] for load in LAB_LOADS_MM[:loads]]
    results = [fine_epoch(EpochConditions(midspan_displacement_m=load / 1000), pos, seed=seed0 + k,
                          min_points=min_points) for k, (pos, load) in enumerate(cases)]
    base, base_truth = results[0][0], results[0][1]
    errs, pts = [], []
    for cents, truth, _, _ in results[1:]:
        e, _ = errors(base, base_truth, cents, truth, normal_mode=mode)
        errs += [x[1] for x in e]
        pts += [c.n_points for c in cents.values()]
    errs = np.array(errs)
    return float(np.sqrt(np.mean(errs ** 2))), float(np.max(np.abs(errs))), int(np.min(pts)), int(np.median(pts))


def honesty(n_epochs: int, seed0: int = 500):
    rng = np.random.default_rng(seed0)
    base = fine_epoch(EpochConditions(), ScannerSetup.random(rng), seed=seed0)
    ratios, errs = [], []
    for k in range(n_epochs):
        cond = EpochConditions(midspan_displacement_m=rng.uniform(-0.012, 0.004))
        ep = fine_epoch(cond, ScannerSetup.random(rng), seed=seed0 + 1 + k)
        e, _ = errors(base[0], base[1], ep[0], ep[1])
        ratios += [abs(x[1]) / x[2] for x in e]
        errs += [x[1] for x in e]
    ratios = np.array(ratios)
    return float(np.mean(ratios < 2)), float(np.sqrt(np.mean(np.square(errs)))), float(np.median(ratios))


def traps(moves_tried: int = 5):
    base = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=900)
    tie = fine_epoch(EpochConditions(midspan_displacement_m=-0.005, cable_ties=("R1",)), LAB_POSITIONS[1], seed=901)
    e_tie, _ = errors(base[0], base[1], tie[0], tie[1])
    moves = []
    for target, vec in (("R4", (0.005, 0, 0)), ("R4", (0, 0.005, 0)), ("R4", (0, 0, 0.005)), ("R1", (0, 0.005, 0)),
                        ("R2", (0.0035, 0, -0.0035)))[:moves_tried]:
        moved = fine_epoch(EpochConditions(midspan_displacement_m=-0.005, moved_targets={target: vec}),
                           LAB_POSITIONS[2], seed=902)
        e_mov, res = errors(base[0], base[1], moved[0], moved[1])
        moves.append((target, vec, [c.reflector for c in res.reference_checks if c.moved],
                      [c.reflector for c in res.reference_checks if c.suspect], res.flags,
                      max(abs(x[1]) for x in e_mov)))
    return max(abs(x[1]) for x in e_tie), tie[0]["R1"].flags, moves


def main(n_epochs: int = 40, *, small: bool = False) -> None:
    cases = dict(positions=2, loads=2) if small else {}
    print("Lab design (" + ("2 positions x 2 loads" if small else "3 positions x 4 loads")
          + ", vs case 1), 5 mm range noise:")
    print(f"{'points/target':>14} {'RMS mm':>8} {'max mm':>8} {'min n':>7} {'median n':>9}")
    lab = {}
    for mp in (1000,) if small else (500, 1000, 2000, 4000):
        rms, mx, nmin, nmed = lab[mp] = lab_design(mp, **cases)
        print(f"{mp:>14} {rms * 1000:8.3f} {mx * 1000:8.3f} {nmin:7d} {nmed:9d}")
    rms, mx, _, _ = lab_design(1000, mode="epoch", **cases)
    print(f"  (normal re-fitted per epoch as in the dissertation, 1000 points: RMS {rms * 1000:.3f} mm, max {mx * 1000:.3f} mm)")
    frac, rms_h, med = honesty(n_epochs)
    print(f"Honest sigma over {n_epochs} random epochs x 5 targets: |error|/sigma < 2 for {frac * 100:.1f} % "
          f"(median ratio {med:.2f}); RMS error {rms_h * 1000:.3f} mm")
    e_tie, flags, moves = traps(2 if small else 5)
    print(f"Cable tie beside R1: max displacement error {e_tie * 1000:.3f} mm (R1 flags: {', '.join(flags)})")
    for target, vec, moved, suspect, eflags, err in moves:
        print(f"{target} moved by {np.round(np.array(vec) * 1000, 1)} mm (bridge frame): flagged moved {moved}, "
              f"suspect {suspect}, epoch flags {list(eflags)}, max displacement error {err * 1000:.3f} mm")
    figures(lab_rms_mm=lab[1000][0] * 1000, lab_max_mm=lab[1000][1] * 1000, lab_min_points=lab[1000][2],
            lab_epoch_normal_rms_mm=rms * 1000, honest_within_2sigma=frac, honest_rms_mm=rms_h * 1000,
            tie_max_error_mm=e_tie * 1000, moves_tried=len(moves),
            moves_caught=sum(1 for m in moves if m[2] or m[3] or m[4]))


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 4 if _small else 40, small=_small)

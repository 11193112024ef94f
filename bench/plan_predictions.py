"""Honest predictions (issue 14): what the plan and the station advisor promise against what is scanned.

Full ray-cast simulation, three bridges unlike each other (spans 25 / 40 / 60 m, decks 4 / 6 / 10 m
wide, 5 / 5 / 8 deck targets on two or three girder lines), a levelled scanner 6-25 m to either
side, somewhere new every visit; a baseline visit per bridge, then 10 visits with the deck sagging.
Every visit runs the product's own chain: coarse scan -> detection and identification against a
layout with 2 cm errors -> plan (Riegl VZ-1000 profile) -> fine scans of the planned windows ->
centroids -> displacements against the baseline.

Printed:

1. Points: the plan's expected points on each target against the points the simulator put on it
   (beam centre on the disc), for detected and predicted windows; and every target's points against
   the 1000 requested.
2. Sigma: the station advisor's predicted sigma of each deck target's displacement (made before
   the visit, from the layout and the baseline's centroids) against the sigma processing reports.
3. Detection recall of the coarse scan by coarse step, range and incidence.
4. The time model against the dissertation's VZ-1000 figures (section 4.3.2).

Usage: ``./run bench plan_predictions`` (about 5 minutes on two cores; ``--small``: the 25 m bridge, one visit after
the baseline, at a 0.08 degree coarse step).
"""
from __future__ import annotations

import math

import numpy as np
from _dissertation import time_figures  # noqa: E402  (bench/ is on the path when run as a script)
from _harness import figures, small_mode

from lidar.displacement import Observation, compute_displacements
from lidar.layout import layout_from_model
from lidar.pipeline import analyse_coarse, measure_targets, plan_from_coarse
from lidar.scan import Scan
from lidar.scanner_catalogue import get_scanner
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.bridge import Target
from lidar.stations import predict_station

VZ = get_scanner("Riegl VZ-1000")
STEPS = (0.03, 0.05, 0.08)


def _bridge(span, width, bottom, lines, fractions) -> BridgeModel:
    face1, face2 = 1.0 + 0.001, span - 1.0 - 0.001
    hw = min(width / 2 - 0.5, 2.0)
    refs = [Target("R1", "reference", (face1, -hw, 2.0), (1, 0, 0)), Target("R2", "reference", (face1, hw, 0.7 * bottom), (1, 0, 0)),
            Target("R3", "reference", (face2, hw, 2.0), (-1, 0, 0)), Target("R4", "reference", (face2, -hw, 0.7 * bottom), (-1, 0, 0))]
    deck = [Target(f"M{k + 1}", "measurement", (f * span, lines[k % len(lines)], bottom - 0.001), (0, 0, -1))
            for k, f in enumerate(fractions)]
    return BridgeModel(span_m=span, deck_width_m=width, deck_bottom_m=bottom, pier_width_m=max(width - 1, 3.0),
                       targets=tuple(refs + deck))


BRIDGES = {
    "25 m / 4 m deck": _bridge(25.0, 4.0, 5.0, (-1.2, 1.2), (0.2, 0.35, 0.5, 0.65, 0.8)),
    "40 m / 6 m deck": BridgeModel(),
    "60 m / 10 m deck": _bridge(60.0, 10.0, 9.0, (-4.0, 0.0, 4.0), (0.15, 0.27, 0.38, 0.5, 0.62, 0.73, 0.85, 0.5)),
}


def _station(rng, model) -> ScannerSetup:
    side = rng.choice((-1.0, 1.0))
    across = side * (model.deck_width_m / 2 + rng.uniform(6.0, 15.0))
    return ScannerSetup((rng.uniform(0.3, 0.7) * model.span_m, across, rng.uniform(1.2, 1.8)),
                        heading_deg=rng.uniform(0, 360), pitch_deg=rng.normal(0, 0.02), roll_deg=rng.normal(0, 0.02))


def visit(model, layout, setup, midspan_m, step, rng):
    """One visit through the product's chain; returns centroids, plan, truth counts, coarse analysis."""
    scene = BridgeScene(model, EpochConditions(midspan_displacement_m=midspan_m), setup, profile=VZ)
    coarse, _ = scene.scan(scene.coarse_window(step), rng=rng)
    analysis = analyse_coarse(coarse, layout)
    plan = plan_from_coarse(analysis, layout, profile=VZ)
    scans, counts = [], {}
    for roi in plan.rois:
        s, t = scene.scan(roi.window, rng=rng)
        scans.append(s)
        counts[roi.reflector] = t.target(roi.reflector).points_on_target
    fine = Scan.concatenate(scans)
    cents = {k: c for k, c in measure_targets(fine, plan, layout, profile=VZ).items() if c.found}
    return cents, plan, counts, analysis, scene


def incidence_and_range(scene, tid):
    t = scene.truth().target(tid)
    c = np.asarray(t.centre_socs_m)
    r = float(np.linalg.norm(c))
    return math.degrees(math.acos(abs(np.asarray(t.normal_socs) @ (c / r)))), r


def run(stations_per_bridge: int = 10, seed: int = 7, *, bridges: tuple[str, ...] = tuple(BRIDGES),
        steps: tuple[float, ...] = STEPS):
    rng = np.random.default_rng(seed)
    points_rows, sigma_rows, recall_rows = [], [], []
    for name in bridges:
        model = BRIDGES[name]
        layout = layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(1))
        groups = dict(zip(layout.ids, layout.groups, strict=False))
        base_setup = _station(rng, model)
        base, *_ = visit(model, layout, base_setup, 0.0, 0.05, rng)
        base_obs = {k: Observation(c.xyz_socs, c.cov) for k, c in base.items()}
        for k in range(stations_per_bridge):
            setup = _station(rng, model)
            step = steps[k % len(steps)]
            # predicted before the visit: layout + baseline only (the layout's frame is the bridge frame here)
            pred = predict_station(layout, setup.position_m, profile=VZ, baseline=base_obs)
            cents, plan, counts, analysis, scene = visit(model, layout, setup, -rng.uniform(0.002, 0.012), step, rng)
            missing = set(analysis.identification.missing)
            for roi in plan.rois:
                inc, r = incidence_and_range(scene, roi.reflector)
                got = counts.get(roi.reflector, 0)
                n_est = cents[roi.reflector].n_points if roi.reflector in cents else 0
                points_rows.append((name, roi.reflector, roi.reflector in missing, roi.expected_target_points, got,
                                    n_est, inc, r))
                m = analysis.identification.match(roi.reflector)
                blob = m.detection is not None and not analysis.detections.detections[m.detection].guided
                recall_rows.append((step, r, inc, roi.reflector not in missing, blob))
            res = compute_displacements(base, cents, groups)
            for d in res.displacements:
                if np.isfinite(d.sigma_m) and d.reflector in pred.predicted_sigma_mm:
                    sigma_rows.append((name, k, d.reflector, pred.predicted_sigma_mm[d.reflector], d.sigma_m * 1000,
                                       d.displacement_m))
            print(f"  {name}: station {k + 1} at {np.round(setup.position_m, 1)} step {step} deg: "
                  f"{len(missing)} predicted window(s), plan {plan.total_seconds / 60:.0f} min", flush=True)
    return points_rows, sigma_rows, recall_rows


def report_points(rows):
    print("\n1. Points on the target: plan against the simulator (beam centre on the disc)")
    print("| windows | n | plan/scanned median | within ±30 % | min scanned / 1000 requested |")
    print("|---|---|---|---|---|")
    for label, sel in (("detected", [r for r in rows if not r[2]]), ("predicted", [r for r in rows if r[2]]),
                       ("all", rows)):
        if not sel:
            print(f"| {label} | 0 | - | - | - |")
            continue
        ratio = np.array([r[3] / max(r[4], 1) for r in sel])
        within = np.mean(np.abs(ratio - 1) <= 0.3) * 100
        print(f"| {label} | {len(sel)} | {np.median(ratio):.2f} | {within:.0f} % | {min(r[4] for r in sel) / 1000:.2f} |")
    limited = [r for r in rows if r[3] < 0.999 * 1000]
    able = [r for r in rows if r[3] >= 0.999 * 1000]
    if able:
        print(f"Targets the instrument can give 1000 points from their station: {len(able)}; the fewest scanned "
              f"{min(r[4] for r in able)} ({min(r[4] for r in able) / 1000:.2f}x the request).")
    if limited:
        print(f"Targets its finest steps cannot give 1000 points (the plan says so in the window's notes): "
              f"{len(limited)}, e.g. " + ", ".join(f"{r[0]} {r[1]} at {r[7]:.0f} m, {r[6]:.0f} deg: {r[3]} planned, "
                                                   f"{r[4]} scanned" for r in limited[:3]))
    est = np.array([r[5] / max(r[4], 1) for r in rows if r[5]])
    print(f"The centroid estimator keeps {np.median(est):.2f}x (5-95 %: {np.percentile(est, 5):.2f}-"
          f"{np.percentile(est, 95):.2f}x) the beam-centre count: rim points a beam only partly covers.")


def report_sigma(rows):
    print("\n2. Predicted sigma of each deck target's displacement against the sigma processing reports")
    q = np.array([r[3] / r[4] for r in rows])
    print("| targets | median predicted/reported | within ±30 % | 5-95 % |")
    print("|---|---|---|---|")
    print(f"| {len(q)} | {np.median(q):.2f} | {np.mean(np.abs(q - 1) <= 0.3) * 100:.0f} % | "
          f"{np.percentile(q, 5):.2f}-{np.percentile(q, 95):.2f} |")
    for name in BRIDGES:
        sub = np.array([r[3] / r[4] for r in rows if r[0] == name])
        if sub.size:
            print(f"  {name}: {sub.size} targets, median {np.median(sub):.2f}, "
                  f"{np.mean(np.abs(sub - 1) <= 0.3) * 100:.0f} % within ±30 %")


def report_recall(rows):
    print("\n3. Coarse-scan detection recall (a window that is not detected is predicted from the layout):")
    print("   blob search alone / with the guided second look at the predicted positions")
    arr = np.array(rows, dtype=float)

    def pct(sel):
        return f"{sel[:, 4].mean() * 100:.0f} % / {sel[:, 3].mean() * 100:.0f} %" if len(sel) else "-"
    print("| coarse step | targets | recall |")
    print("|---|---|---|")
    for s in STEPS:
        sel = arr[arr[:, 0] == s]
        print(f"| {s:.2f} deg | {len(sel)} | {pct(sel)} |")
    print("| range | targets | recall |  | incidence | targets | recall |")
    print("|---|---|---|---|---|---|---|")
    rbins, ibins = (0, 12, 18, 25, 40, 100), (0, 45, 60, 70, 80, 90)
    for k in range(5):
        rs = arr[(arr[:, 1] >= rbins[k]) & (arr[:, 1] < rbins[k + 1])]
        ins = arr[(arr[:, 2] >= ibins[k]) & (arr[:, 2] < ibins[k + 1])]
        print(f"| {rbins[k]}-{rbins[k + 1]} m | {len(rs)} | {pct(rs)} |  | {ibins[k]}-{ibins[k + 1]} deg | {len(ins)} | "
              f"{pct(ins)} |")
    print("A target none of whose coarse samples falls on the disc (a 50 mm disc at 75 deg spans 0.04 deg at 20 m) "
          "cannot be detected at that step; its window is predicted from the layout and still holds (table 1).")


def report_time_model():
    """The dissertation's VZ-1000 field figures (section 4.3.2): 3 min for 1000 points on a pier target, 7 min for
    25,000 points at midspan, under an hour for the visit (10 targets). The scanner's position is not given: ranges
    of 15-30 m to the pier targets and 8-12 m to the midspan targets are assumed."""
    f = time_figures(VZ)
    print("\n4. Time model (Riegl VZ-1000 profile) against the dissertation's field visit")
    print("| window | dissertation | ours (range) |")
    print("|---|---|---|")
    print(f"| pier target, 1000 points | 3 min | {f['pier_min'][0]:.1f}-{f['pier_min'][1]:.1f} min at 15-30 m (calibrated) |")
    print(f"| midspan target, 25,000 points | 7 min | {f['mid_min'][0]:.1f}-{f['mid_min'][1]:.1f} min at 8-12 m "
          f"({f['mid_points'][0]:,}-{f['mid_points'][1]:,} points reachable) |")
    print(f"| visit, 4 pier + 6 deck targets at 1000 points | < 60 min | {f['visit_min']:.0f} min |")
    print(f"| full-resolution scan of everything (0.001/0.006 deg, 360 deg) | > 10 h | {f['full_h']:.0f} h |")
    print("Matched: the pier figure (the per-window overhead of 120 s is calibrated on it) and the visit. "
          "The midspan figure depends on the unstated range; the finest steps cap what one window can give.")


def main():
    small, _ = small_mode()
    print("Honest predictions: plan and station advisor against the simulated visits")
    points, sigmas, recall = run(**(dict(stations_per_bridge=1, bridges=tuple(BRIDGES)[:1], steps=(0.08,))
                                    if small else {}))
    report_points(points)
    report_sigma(sigmas)
    report_recall(recall)
    report_time_model()
    q = np.array([r[3] / r[4] for r in sigmas])
    figures(windows=len(points), points_plan_to_scanned_median=float(np.median([r[3] / max(r[4], 1) for r in points])),
            sigma_predicted_to_reported_median=float(np.median(q)) if q.size else None,
            recall_with_guided=float(np.mean([r[3] for r in recall])))


if __name__ == "__main__":
    main()

"""Commands working on single scan files, outside any campaign: detect, plan-file, centroids, simulate."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from app.cli.output import dump_json, table
from app.cli.progress import progress_bar
from common.errors import InputError
from lidar.angles import spherical_from_xyz
from lidar.io import read_scan
from lidar.layout import layout_from_model, read_layout_csv, write_layout_csv
from lidar.pipeline import analyse_map, measure_targets, plan_from_coarse
from lidar.plan import ScanPlan
from lidar.reflectance_map import reflectance_map_from_file
from lidar.scan import Scan
from lidar.scanner_catalogue import get_scanner
from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
from lidar.simulate.files import simulate_coarse, simulate_fine


def _load(path: Path, progress=None):
    return read_scan(path, progress=progress)


def _layout(path: Path, diameter_mm):
    return read_layout_csv(path, default_diameter_m=(diameter_mm or 50.0) / 1000.0)


def _analyse(args):
    layout = _layout(args.layout, args.diameter_mm)
    with progress_bar("reading and binning") as cb:  # an uncompressed LAS file is binned as it is read
        rmap = reflectance_map_from_file(args.scan, step_deg=getattr(args, "step_deg", None), progress=cb)
    with progress_bar("analysing") as cb:
        coarse = analyse_map(rmap, layout, threshold=getattr(args, "threshold", None), progress=cb)
    return layout, coarse


def _match_rows(coarse):
    rows = []
    for m in coarse.identification.matches:
        t, p, r = spherical_from_xyz(np.array([m.xyz_socs]))
        rows.append({"id": m.id, "group": m.group, "status": "predicted" if m.predicted else "detected",
                     "theta_deg": float(t[0]), "phi_deg": float(p[0]), "range_m": float(r[0]),
                     "residual_m": m.residual_m, "x": m.xyz_socs[0], "y": m.xyz_socs[1], "z": m.xyz_socs[2]})
    return rows


def cmd_detect(args) -> int:
    _, coarse = _analyse(args)
    det = coarse.detections
    rows = _match_rows(coarse)
    extras = [det.detections[i] for i in coarse.identification.extra_detections]
    if args.png:
        # local: matplotlib costs detect and plan-file without --png 0.35 s of start-up (measured)
        from lidar.figures import reflectance_map_figure, save_figure

        save_figure(reflectance_map_figure(coarse.reflectance_map, detections=det,
                                           identification=coarse.identification, title=args.scan.name), args.png)
    if args.json:
        dump_json({"scan": str(args.scan), "threshold": det.threshold, "map_step_deg": det.map_step_deg,
                   "fit_rms_m": coarse.identification.rms_m, "targets": rows,
                   "extra_detections": [d.__dict__ for d in extras],
                   "missing": list(coarse.identification.missing), "missing_why": dict(coarse.missing_why)})
        return 0
    print(f"{args.scan}: {len(det.detections)} bright blobs (threshold {det.threshold:.2f}, "
          f"map cell {det.map_step_deg:.4f} deg); layout fit RMS {coarse.identification.rms_m * 1000:.0f} mm")
    table(rows, ["id", "group", "status", "theta_deg", "phi_deg", "range_m", "residual_m"])
    if extras:
        print(f"{len(extras)} bright object(s) not in the layout: " +
              "; ".join(f"theta {d.theta_deg:.3f} phi {d.phi_deg:.3f} range {d.range_m:.2f} m" for d in extras))
    if coarse.missing_note:
        print(coarse.missing_note)
    return 0


def cmd_plan_file(args) -> int:
    profile = get_scanner(args.scanner)
    layout, coarse = _analyse(args)
    plan = plan_from_coarse(coarse, layout, epoch=args.epoch, min_points=args.min_points,
                            budget_seconds=args.budget_min * 60.0, profile=profile)
    plan.save(args.out)
    if args.png:
        # local: matplotlib costs detect and plan-file without --png 0.35 s of start-up (measured)
        from lidar.figures import reflectance_map_figure, save_figure

        save_figure(reflectance_map_figure(coarse.reflectance_map, detections=coarse.detections,
                                           identification=coarse.identification, rois=plan.rois,
                                           title=f"{args.scan.name}: plan"), args.png)
    if args.json:
        dump_json(plan.to_json())
        return 0
    print(f"wrote {args.out}: {len(plan.rois)} windows, {plan.total_seconds / 60:.1f} min "
          f"(budget {plan.budget_seconds / 60:.0f} min), {plan.points_per_target} points per target")
    table([r.to_json() for r in plan.rois], ["reflector", "group", "theta_step_deg", "phi_step_deg", "range_m",
                                             "expected_target_points", "expected_points", "expected_seconds"])
    for w in plan.warnings:
        print(f"warning: {w}")
    return 0


def centroid_rows(cents) -> list[dict]:
    rows = []
    for k, c in cents.items():
        sig = c.sigma_m * 1000 if c.found else [float("nan")] * 3
        rows.append({"reflector": k, "found": c.found, "x": float(c.xyz_socs[0]), "y": float(c.xyz_socs[1]),
                     "z": float(c.xyz_socs[2]), "sx_mm": float(sig[0]), "sy_mm": float(sig[1]),
                     "sz_mm": float(sig[2]), "n": c.n_points, "threshold": c.threshold,
                     "separability": c.separability, "flags": list(c.flags)})
    return rows


def cmd_centroids(args) -> int:
    plan = ScanPlan.load(args.plan)
    layout = _layout(args.layout, None) if args.layout else None
    with progress_bar("reading") as cb:
        scans = [_load(p, cb) for p in args.scans]
    fine = Scan.concatenate(scans) if len(scans) > 1 else scans[0]
    cents = measure_targets(fine, plan, layout)
    rows = centroid_rows(cents)
    if args.json:
        dump_json(rows)
    else:
        table(rows, ["reflector", "n", "x", "y", "z", "sx_mm", "sy_mm", "sz_mm", "separability", "flags"])
    return 0


def _parse_move(text: str):
    try:
        rid, vec = text.split(":")
        dx, dy, dz = (float(v) for v in vec.split(","))
    except ValueError:
        raise InputError(f"--move expects ID:DX,DY,DZ in metres, got {text!r}") from None
    return rid, (dx, dy, dz)


def cmd_simulate(args) -> int:
    if args.fine:
        plan = ScanPlan.load(args.fine)
        path, truth = simulate_fine(args.folder, plan.rois)
        print(f"wrote {path} ({len(plan.rois)} windows)")
        return 0
    try:
        position = tuple(float(v) for v in args.position.split(","))
        if len(position) != 3:
            raise ValueError
    except ValueError:
        raise InputError(f"--position expects x,y,z in metres, got {args.position!r}") from None
    cond = EpochConditions(midspan_displacement_m=args.midspan_mm / 1000.0,
                           moved_targets=dict(_parse_move(m) for m in args.move),
                           occluded=tuple(args.occlude), cable_ties=tuple(args.cable_tie))
    setup = ScannerSetup(position, heading_deg=args.heading_deg)
    path, truth = simulate_coarse(args.folder, setup=setup, conditions=cond, seed=args.seed,
                                  coarse_step_deg=args.coarse_step_deg)
    layout_path = Path(args.folder) / "layout.csv"
    if not layout_path.exists():
        write_layout_csv(layout_from_model(BridgeModel(), noise_m=0.02, rng=np.random.default_rng(99)), layout_path)
    print(f"wrote {path}, {layout_path} and truth.json")
    return 0

"""Pipeline speed against plain laspy + numpy baselines (issue 3).

1. Coarse scan (LAS) -> detections (read + reflectance map + detection), against laspy's plain read
   plus numpy computing every point's two angles. Target: <= 1.5x; peak memory <= 2x the decoded
   point records.
2. One whole epoch (coarse + fine, LAZ) from files to centroids, against laspy's plain decoding of
   the same files. Target: <= 2x.

The coarse scan is a simulated whole-bridge scan at a fine enough step to hold N points (default
20 M). Usage: ``./run bench bench_pipeline [N_POINTS]`` (``--small``: 300,000 points, one process each).
"""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
from _harness import OUT, figures, measure, row, small_mode

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def make_files(n_target: int, *, fresh: bool = False) -> tuple[Path, Path, Path, Path]:
    """The scene's files in ``bench/out/pipeline_N`` (made once; ``fresh``: made again, as the small mode does so
    that files an older version wrote are not measured)."""
    from lidar.io import write_scan
    from lidar.layout import layout_from_model, write_layout_csv
    from lidar.pipeline import analyse_coarse, plan_from_coarse
    from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
    from lidar.simulate.files import simulate_fine

    folder = OUT / f"pipeline_{n_target}"
    coarse_las, coarse_laz = folder / "coarse.las", folder / "coarse.laz"
    fine_laz, layout_csv = folder / "fine.laz", folder / "layout.csv"
    if fresh:
        shutil.rmtree(folder, ignore_errors=True)
    if fine_laz.exists():
        return coarse_las, coarse_laz, fine_laz, layout_csv
    folder.mkdir(parents=True, exist_ok=True)
    setup = ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0)
    scene = BridgeScene(BridgeModel(), EpochConditions(midspan_displacement_m=-0.004), setup)
    w0 = scene.coarse_window(step_deg=0.05)
    # about half the directions hit something; choose the step for n_target returns
    step = 0.05 * np.sqrt(0.55 * w0.n_directions / n_target)
    from lidar.simulate.files import save_scene

    scan, _ = scene.scan(scene.coarse_window(step_deg=step), rng=np.random.default_rng(0))
    save_scene(folder, setup, EpochConditions(midspan_displacement_m=-0.004), 0, step)
    write_scan(scan, coarse_las)
    write_scan(scan, coarse_laz)
    layout = layout_from_model(BridgeModel(), noise_m=0.02)
    write_layout_csv(layout, layout_csv)
    coarse = analyse_coarse(scan, layout)
    plan = plan_from_coarse(coarse, layout)
    plan.save(folder / "plan.json")
    simulate_fine(folder, plan.rois)
    return coarse_las, coarse_laz, fine_laz, layout_csv


def main(n: int = 20_000_000, *, repeat: int = 3, fresh: bool = False) -> None:
    las, laz, fine, layout = make_files(n, fresh=fresh)
    import laspy

    with laspy.open(las) as r:
        n_pts = r.header.point_count
        rec_mb = n_pts * r.header.point_format.size / 2**20
    print(f"coarse scan: {n_pts:,} points ({rec_mb:.0f} MiB of point records); best of {repeat} fresh processes")
    base = measure("import laspy, numpy as np", f"""
las = laspy.read({str(las)!r})
x, y, z = np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)
theta = np.degrees(np.arctan2(np.hypot(x, y), z)); phi = np.degrees(np.arctan2(y, x)) % 360
""", repeat=repeat)
    ours = measure("from lidar.io import read_scan; from lidar.reflectance_map import reflectance_map\n"
                   "from lidar.detection import detect_reflectors", f"""
scan = read_scan({str(las)!r})
det = detect_reflectors(reflectance_map(scan.xyz_socs, scan.intensity))
""", repeat=repeat)
    print(row("laspy.read + numpy angles (baseline)", base))
    print(row("BridgeSurvey read + map + detection", ours, base))
    print(f"  RESULT coarse->detections: time x{ours['seconds'] / base['seconds']:.2f} of baseline (target <= 1.5); "
          f"peak memory x{ours['peak_mb'] / rec_mb:.2f} of the decoded point records (target <= 2.0)")

    base2 = measure("import laspy", f"a = laspy.read({str(laz)!r}); b = laspy.read({str(fine)!r})", repeat=repeat)
    ours2 = measure("""
from lidar.io import read_scan
from lidar.layout import read_layout_csv
from lidar.pipeline import analyse_coarse, plan_from_coarse, measure_targets
""", f"""
layout = read_layout_csv({str(layout)!r})
coarse = analyse_coarse(read_scan({str(laz)!r}), layout)
plan = plan_from_coarse(coarse, layout)
cents = measure_targets(read_scan({str(fine)!r}), plan, layout)
assert sum(c.found for c in cents.values()) == len(layout)
""", repeat=repeat)
    print(row("laspy.read of coarse.laz + fine.laz (baseline)", base2))
    print(row("BridgeSurvey whole epoch, files -> centroids", ours2, base2))
    print(f"  RESULT whole epoch (LAZ): time x{ours2['seconds'] / base2['seconds']:.2f} of laspy decoding (target <= 2.0)")
    figures(points=n_pts, coarse_time_ratio=ours["seconds"] / base["seconds"],
            coarse_peak_ratio=ours["peak_mb"] / rec_mb, epoch_time_ratio=ours2["seconds"] / base2["seconds"])


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 300_000 if _small else 20_000_000, repeat=1 if _small else 3, fresh=_small)

"""Adding and processing epoch 100 of a campaign costs no more than epoch 2 (issue 4).

One simulated visit is imported again and again as new epochs; each copy differs only in the LAS
header's project GUID, so the checksums differ and the processing work is the same every time.
Usage: ``./run bench bench_campaign [N_EPOCHS]`` (default 100; ``--small``: 5, coarse scans at 0.12 degrees).
"""
from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _harness import OUT, figures, small_mode  # noqa: E402


def variant(src: Path, dst: Path, k: int) -> Path:
    blob = bytearray(src.read_bytes())
    blob[8:24] = k.to_bytes(16, "little")  # project GUID: not used by any reader
    dst.write_bytes(bytes(blob))
    return dst


def build_campaign(work: Path, n: int, *, report_every: int = 10, coarse_step_deg: float = 0.06
                   ) -> tuple[Path, dict[int, float]]:
    """A campaign of ``n`` processed epochs in ``work/camp``; returns it and each epoch's processing seconds.

    Every epoch's coarse scan is the same visit at ``coarse_step_deg`` (0.06 degrees: 1.2 M points).
    """
    from lidar.io import read_scan, write_scan
    from lidar.layout import layout_from_model, read_layout_csv, write_layout_csv
    from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
    from lidar.simulate.files import simulate_coarse, simulate_fine
    from projects.processing.stages import plan_epoch, process
    from projects.store.campaign import Campaign

    field = work / "field"
    simulate_coarse(field, setup=ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0),
                    conditions=EpochConditions(midspan_displacement_m=-0.003), seed=1, coarse_step_deg=coarse_step_deg)
    write_scan(read_scan(field / "coarse.laz"), field / "coarse.las")
    write_layout_csv(layout_from_model(BridgeModel(), noise_m=0.02), field / "layout.csv")
    camp = Campaign.create(work / "camp", name="bench", layout=read_layout_csv(field / "layout.csv"), span_m=40)
    camp.set_limit("*", "kr-rail:0-200")
    times = {}
    fine_las = None
    with camp:
        for k in range(1, n + 1):
            label = f"E{k:03d}"
            coarse = variant(field / "coarse.las", work / f"c{k}.las", k)
            t0 = time.perf_counter()
            when = "2026-01-01T00:00+00:00" if k == 1 else f"2026-01-{1 + (k % 28):02d}T{k % 24:02d}:00+00:00"
            camp.add_epoch(label, when, coarse)
            plan = plan_epoch(camp, label)
            t_plan = time.perf_counter() - t0
            if fine_las is None:
                simulate_fine(field, plan.rois)
                write_scan(read_scan(field / "fine.laz"), field / "fine.las")
                fine_las = field / "fine.las"
            fine = variant(fine_las, work / f"f{k}.las", k)
            t1 = time.perf_counter()
            camp.import_files(label, [fine], "fine")
            summary = process(camp, [label])
            times[k] = t_plan + time.perf_counter() - t1
            coarse.unlink()
            fine.unlink()
            if k in (2, n) or k % report_every == 0:
                print(f"epoch {k:3d}: add + plan + add fine + process {times[k]:.2f} s "
                      f"({len(summary.displacement_epochs)} displacement set(s) computed)", flush=True)
    return work / "camp", times


def main(n: int = 100, *, coarse_step_deg: float = 0.06) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="bench_campaign_", dir=OUT))  # under bench/out/, which git ignores
    try:
        _, times = build_campaign(work, n, coarse_step_deg=coarse_step_deg)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    med_early = float(np.median([times[k] for k in (2, 3, 4)]))
    med_late = float(np.median([times[k] for k in (n - 2, n - 1, n)]))
    print(f"RESULT epoch {n} costs x{med_late / med_early:.2f} of epoch 2 (median of 3 around each; target <= 1.0 "
          f"within noise)")
    figures(epochs=len(times), ratio_last_to_early=med_late / med_early, early_seconds=med_early)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 5 if _small else 100, coarse_step_deg=0.12 if _small else 0.06)

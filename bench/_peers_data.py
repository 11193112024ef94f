"""Data of ``./run bench peers``: a processed 3-visit campaign (coarse scans at 0.06 degrees, 1.2-1.3 M points)
and a 19 M-point coarse scan as LAS, simulated once into ``bench/out/peers`` (nothing of it is committed).

The small mode's data (``bench/out/peers-small``): the same campaign at a coarser step and a smaller big scan."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "out" / "peers"
BIG_POINTS = 19_100_000
#: The small mode's folder, coarse step of the campaign's visits and points of the big scan.
SMALL_OUT = ROOT / "bench" / "out" / "peers-small"
SMALL_STEP_DEG = 0.12
SMALL_POINTS = 400_000


def campaign(folder: Path = OUT, *, step_deg: float = 0.06) -> Path:
    """The tests' three visits (0, -4 and -7 mm at midspan), imported, fine-scanned and processed."""
    from lidar.layout import layout_from_model, write_layout_csv
    from lidar.simulate.files import simulate_coarse
    from tests.projects.campaign_helpers import build_processed_campaign
    from tests.projects.conftest import MODEL, VISITS

    camp = folder / "campaign"
    if (camp / "done").exists():
        return camp
    field = folder / "field"
    field.mkdir(parents=True, exist_ok=True)
    write_layout_csv(layout_from_model(MODEL, noise_m=0.02, rng=np.random.default_rng(1)), field / "layout.csv")
    for k, (setup, cond) in enumerate(VISITS):
        simulate_coarse(field / f"v{k}", setup=setup, conditions=cond, model=MODEL, seed=10 + k,
                        coarse_step_deg=step_deg)
    if camp.exists():
        import shutil

        shutil.rmtree(camp)
    build_processed_campaign(field, camp)
    (camp / "done").write_text("1")
    return camp


def big_scan(folder: Path = OUT, *, points: int = BIG_POINTS) -> tuple[Path, Path, float]:
    """A whole-bridge coarse scan of about 19.1 M points (LAS, format 6) and its layout; returns the step too."""
    from lidar.io import write_scan
    from lidar.layout import layout_from_model, write_layout_csv
    from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup

    folder = folder / "big"
    las, layout = folder / "coarse.las", folder / "layout.csv"
    meta = folder / "meta.json"
    if meta.exists():
        return las, layout, float(json.loads(meta.read_text())["step_deg"])
    folder.mkdir(parents=True, exist_ok=True)
    scene = BridgeScene(BridgeModel(), EpochConditions(midspan_displacement_m=-0.004),
                        ScannerSetup((20.0, -12.0, 1.5), heading_deg=30.0))
    w0 = scene.coarse_window(step_deg=0.05)
    step = 0.05 * np.sqrt(0.55 * w0.n_directions / points)
    step = float(np.round(step, 4))
    scan, _ = scene.scan(scene.coarse_window(step_deg=step), rng=np.random.default_rng(0))
    write_scan(scan, las)
    write_layout_csv(layout_from_model(BridgeModel(), noise_m=0.02), layout)
    meta.write_text(json.dumps({"points": len(scan), "step_deg": step}))
    return las, layout, step


if __name__ == "__main__":
    print(campaign())
    print(big_scan())

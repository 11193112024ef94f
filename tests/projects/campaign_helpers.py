"""Helpers of the campaign tests: a byte-level snapshot of a campaign and a processed 3-visit campaign."""
from __future__ import annotations

import hashlib
import sqlite3
from pathlib import Path


def snapshot(folder: Path) -> dict:
    """Everything a campaign holds: file checksums plus a dump of the database."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and p.name not in (".lock",) and not p.name.endswith(("-wal", "-shm", "-wal.owner")):
            if p.suffix == ".sqlite":
                conn = sqlite3.connect(p)
                out[str(p.relative_to(folder))] = "\n".join(conn.iterdump())
                conn.close()
            else:
                out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def build_processed_campaign(field: Path, folder: Path, *, name: str = "Test bridge") -> Path:
    """The three visits of the ``field`` fixture imported, fine-scanned from their plans and processed."""
    from lidar.layout import read_layout_csv
    from lidar.simulate.files import simulate_fine
    from projects.processing.stages import plan_epoch, process
    from projects.store.campaign import Campaign
    from tests.projects.conftest import MODEL, VISITS

    dates = ("2026-03-02T09:00:00+00:00", "2026-03-09T10:00:00+00:00", "2026-03-16T08:30:00+00:00")
    with Campaign.create(folder, name=name, layout=read_layout_csv(field / "layout.csv"), span_m=40.0) as c:
        c.set_limit("*", "kr-rail:0-200")
        for k in range(len(VISITS)):
            label = dates[k][:10]
            visit = field / f"v{k}"
            c.add_epoch(label, dates[k], visit / "coarse.laz", notes=f"visit {k + 1}")
            plan = plan_epoch(c, label)
            fine, _ = simulate_fine(visit, plan.rois, model=MODEL, name="fine-processed.laz")
            c.import_files(label, [fine], "fine")
        process(c)
    return folder

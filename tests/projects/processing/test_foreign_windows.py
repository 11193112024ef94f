"""A visit whose fine scans another planner made (tests/data/foreign-windows, an independent simulator)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from lidar.angles import spherical_from_xyz
from lidar.io import read_scan
from projects.results.state import epoch_state
from projects.store.campaign import Campaign

DATA = Path(__file__).resolve().parents[2] / "data" / "foreign-windows"


@pytest.mark.slow
def test_each_foreign_window_reports_its_own_points_and_the_visit_its_warning(tmp_path, capsys):
    camp = tmp_path / "camp"
    assert main(["init", str(camp), "--name", "FW", "--layout", str(DATA / "layout.csv"),
                 "--target-diameter-mm", "50", "--span-m", "39.9"]) == 0
    assert main(["add-epoch", str(camp), "--date", "2026-03-02T09:00", "--coarse", str(DATA / "coarse.laz"),
                 "--fine", str(DATA / "fine.laz")]) == 0
    assert main(["process", str(camp)]) == 0
    fine = read_scan(DATA / "fine.laz")
    theta, phi, _ = spherical_from_xyz(fine.xyz_socs, out_dtype=np.float32)
    with Campaign.open(camp, writable=False) as c:
        label = c.epochs()[0].label
        plan = c.plan(label)
        cents = c.centroids(label)
        state, flags = epoch_state(c, label)
    assert len(cents) == 10 and all(t.found for t in cents.values())
    for roi in plan.rois:
        if roi.closure:
            continue
        # counted again here, independently: the other planner's windows all hold 215 x 215 points
        assert cents[roi.reflector].n_window == int(roi.window.contains(theta, phi).sum()) == 46225
    assert any(f.startswith("second_bright_object") for f in cents["R2"].flags)  # the cable tie beside R2
    assert state == "warning" and any("second_bright_object" in f for f in flags)

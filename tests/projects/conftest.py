"""A small simulated campaign shared by the campaign tests (3 weekly visits as field files)."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from lidar.layout import layout_from_model, write_layout_csv
from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
from lidar.simulate.files import simulate_coarse

MODEL = BridgeModel()
VISITS = (
    (ScannerSetup((14.0, -12.0, 1.5), heading_deg=40.0), EpochConditions()),
    (ScannerSetup((24.0, -15.0, 1.4), heading_deg=200.0), EpochConditions(midspan_displacement_m=-0.004)),
    (ScannerSetup((30.0, -11.0, 1.6), heading_deg=310.0), EpochConditions(midspan_displacement_m=-0.007)),
)


@pytest.fixture(scope="session")
def field(tmp_path_factory) -> Path:
    """Coarse scans of three visits (fine scans are simulated from each plan by the tests)."""
    root = tmp_path_factory.mktemp("field")
    write_layout_csv(layout_from_model(MODEL, noise_m=0.02, rng=np.random.default_rng(1)), root / "layout.csv")
    for k, (setup, cond) in enumerate(VISITS):
        simulate_coarse(root / f"v{k}", setup=setup, conditions=cond, model=MODEL, seed=10 + k, coarse_step_deg=0.06)
    return root


@pytest.fixture
def field_copy(field, tmp_path) -> Path:
    dst = tmp_path / "field"
    shutil.copytree(field, dst)
    return dst


@pytest.fixture(scope="session")
def processed(field, tmp_path_factory) -> Path:
    """A campaign of the three visits, measured and processed (copy it before changing it)."""
    from tests.projects.campaign_helpers import build_processed_campaign

    return build_processed_campaign(field, tmp_path_factory.mktemp("processed") / "camp")


@pytest.fixture
def processed_copy(processed, tmp_path) -> Path:
    dst = tmp_path / "camp"
    shutil.copytree(processed, dst, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    return dst

"""Shared fixtures: paths to the shipped sample files and small synthetic scans."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidar.scan import Scan, normalise_intensity

DATA = Path(__file__).parent / "data"


@pytest.fixture
def data_dir() -> Path:
    return DATA


@pytest.fixture
def small_scan() -> Scan:
    rng = np.random.default_rng(7)
    xyz = rng.uniform(-30, 30, (2000, 3))
    raw = rng.integers(0, 65535, 2000).astype(np.uint16)
    pose = np.eye(4)
    pose[:3, 3] = (100.0, 200.0, 10.0)
    return Scan(xyz_socs=xyz, intensity=normalise_intensity(raw), intensity_raw=raw, pose=pose, name="small")

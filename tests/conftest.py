"""Shared fixtures: paths to the shipped sample files and small synthetic scans."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from lidar.scan import Scan, normalise_intensity

# Property tests must not depend on how busy the machine is (a shared 2-core machine made Hypothesis's
# input generation "too slow" and can make examples miss its 200 ms deadline): no timing checks.
settings.register_profile("any-machine", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("any-machine")

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

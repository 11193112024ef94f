"""PCL's NDT (pcl_ndt3d) beside Open3D ICP on the same stable parts, against a known motion."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from registration.errors import RegistrationError
from registration.icp import refine_icp
from registration.ndt import ndt_available, parse_transform, refine_ndt
from registration.transform import Transform


def _scene(rng, n=60_000):
    """Ground, two pier blocks and an abutment wall, 3 mm noise, in project coordinates."""
    k = rng.integers(0, 4, n)
    p = np.column_stack([rng.uniform(-5, 45, n), rng.uniform(-8, 8, n), np.zeros(n)])
    p[k == 1, 0] = rng.uniform(0, 2, (k == 1).sum()); p[k == 1, 2] = rng.uniform(0, 7, (k == 1).sum())
    p[k == 2, 0] = 39.0; p[k == 2, 2] = rng.uniform(0, 7, (k == 2).sum())
    p[k == 3, 1] = -2.5 + 0.3 * np.sin(p[k == 3, 0]); p[k == 3, 2] = rng.uniform(0, 7, (k == 3).sum())
    return p + rng.normal(0, 0.003, p.shape) + np.array([4.5e5, 5.4e6, 100.0])


@pytest.mark.skipif(not ndt_available(), reason="PCL's pcl_ndt3d is not installed; ./run installs pcl-tools")
def test_ndt_recovers_a_small_motion_like_icp():
    rng = np.random.default_rng(3)
    tgt = _scene(rng)
    truth = Transform(Rotation.from_euler("z", 0.05, degrees=True).as_matrix(), np.array([0.02, -0.015, 0.01]))
    centre = tgt.mean(axis=0)
    # source = truth^-1 applied around the centre, so truth maps source onto target
    src = (_scene(rng) - centre - truth.translation) @ truth.rotation + centre
    initial = Transform(np.eye(3), np.zeros(3), method="targets")
    checks = np.array([[1.0, 0, 5], [39, 0, 5], [20, -2.5, 3]]) + np.array([4.5e5, 5.4e6, 100.0])
    before = (checks - centre - truth.translation) @ truth.rotation + centre  # the check points in the source
    assert np.abs(initial.apply(before) - checks).max() > 0.015  # the start is off by centimetres
    for refine in (refine_ndt, refine_icp):
        res = refine(src, tgt, initial, offset=centre)
        err_mm = np.abs(res.transform.apply(before) - checks).max() * 1000
        assert err_mm < 5.0, (refine.__name__, err_mm)
        assert res.fitness > 0.5


def test_ndt_refuses_clearly_without_pcl(monkeypatch):
    monkeypatch.setattr("registration.ndt.shutil.which", lambda name: None)
    with pytest.raises(RegistrationError, match="pcl_ndt3d is not installed.*pcl-tools"):
        refine_ndt(np.zeros((200, 3)), np.zeros((200, 3)), Transform.identity())


def test_parse_transform_takes_the_last_matrix_and_refuses_garbage():
    text = ("../a.pcd width: 10 height: 1\n  1 0 0 0.5\n0 1 0 0\n0 0 1 0\n0 0 0 1\nsaving result to b.pcd\n")
    m = parse_transform(text)
    assert m[0, 3] == 0.5
    with pytest.raises(RegistrationError, match="printed no transform"):
        parse_transform("Segmentation fault\n")

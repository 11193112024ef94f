"""The guided second look at targets the blob search missed."""
import numpy as np
import pytest

from lidar.angles import direction_from_angles
from lidar.detection import DetectionResult
from lidar.guided_detection import recover_predicted
from lidar.identification import Identification, TargetMatch
from lidar.reflectance_map import reflectance_map

STEP = 0.08
RANGE = 20.0


def _scene(lit_intensity=0.38, lit_range=RANGE, rng_seed=0):
    """A wall 20 m away sampled every 0.08 deg (background ~0.15) with one partly lit target cell."""
    rng = np.random.default_rng(rng_seed)
    t, p = np.meshgrid(np.arange(80.0, 100.0, STEP), np.arange(-10.0, 10.0, STEP), indexing="ij")
    t, p = t.ravel(), p.ravel()
    d = direction_from_angles(t, p)
    xyz = d * (RANGE / d[:, 0])[:, None]  # a plane x = 20 m
    inten = np.clip(0.15 + rng.normal(0, 0.012, len(t)), 0, 1)
    k = int(np.argmin(np.abs(t - 90.02) + np.abs(p - 1.01)))
    inten[k] = lit_intensity
    xyz[k] *= lit_range / np.linalg.norm(xyz[k])
    return reflectance_map(xyz, inten, step_deg=STEP), xyz[k].copy()


def _predicted_at(xyz):
    m = TargetMatch("M1", "measurement", tuple(xyz), None, None)
    ident = Identification((m,), np.eye(3), np.zeros(3), 0.01, ())
    return DetectionResult((), (), 0.56, STEP), ident


def test_a_dim_lit_cell_where_the_layout_predicts_becomes_the_detection():
    rmap, truth = _scene()
    det, ident = _predicted_at(truth + np.array([0.0, 0.04, -0.03]))  # layout error of a few cm
    det2, ident2 = recover_predicted(rmap, det, ident)
    m = ident2.match("M1")
    assert not m.predicted and det2.detections[m.detection].guided
    assert np.linalg.norm(np.asarray(m.xyz_socs) - truth) < 0.03


@pytest.mark.parametrize("kind", ["no signal", "wrong range", "too far from the prediction"])
def test_nothing_is_invented(kind):
    if kind == "no signal":
        rmap, truth = _scene(lit_intensity=0.16)
        offset = np.zeros(3)
    elif kind == "wrong range":
        rmap, truth = _scene(lit_range=RANGE + 1.5)
        truth = truth / np.linalg.norm(truth) * RANGE
        offset = np.zeros(3)
    else:
        rmap, truth = _scene()
        offset = np.array([0.0, 0.4, 0.0])
    det, ident = _predicted_at(truth + offset)
    det2, ident2 = recover_predicted(rmap, det, ident)
    assert ident2.match("M1").predicted and det2.detections == ()

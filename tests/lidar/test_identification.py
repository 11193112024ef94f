import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lidar.errors import ProcessingError
from lidar.identification import identify_reflectors
from lidar.layout import layout_from_model
from lidar.simulate import BridgeModel

MODEL = BridgeModel()


def scanner_view(rng, drop=(), extra=0):
    """Detections: the true centres in an arbitrary scanner frame, a few mm of noise."""
    rot = Rotation.from_euler("zyx", [rng.uniform(0, 360), 0.3, -0.2], degrees=True).as_matrix()
    t = rng.normal(0, 20, 3)
    ids = [tg.id for tg in MODEL.targets if tg.id not in drop]
    xyz = np.array([MODEL.target(i).centre_m for i in ids]) @ rot.T + t + rng.normal(0, 0.005, (len(ids), 3))
    extras = xyz[:extra] + rng.uniform(0.3, 2.0, (extra, 3)) if extra else np.zeros((0, 3))
    order = rng.permutation(len(ids) + extra)
    allx = np.vstack([xyz, extras])[order]
    names = (ids + [None] * extra)
    return allx, [names[k] for k in order]


def test_identifies_in_any_frame_with_missing_and_extra():
    rng = np.random.default_rng(3)
    layout = layout_from_model(MODEL, noise_m=0.03, rng=rng)
    det, names = scanner_view(rng, drop=("M2", "R3"), extra=3)
    ident = identify_reflectors(det, layout)
    for m in ident.matches:
        if m.detection is not None:
            assert names[m.detection] == m.id
    assert set(ident.missing) == {"M2", "R3"}
    assert len(ident.extra_detections) == 3
    assert ident.rms_m < 0.08


def test_predicted_positions_come_from_the_fit():
    rng = np.random.default_rng(4)
    layout = layout_from_model(MODEL, noise_m=0.0)
    det, names = scanner_view(rng, drop=("M5",))
    ident = identify_reflectors(det, layout)
    m5 = ident.match("M5")
    assert m5.predicted and m5.residual_m is None
    pred = layout.xyz[layout.index("M5")] @ ident.rotation.T + ident.translation
    np.testing.assert_allclose(m5.xyz_socs, pred)


def test_too_few_or_unrelated_detections():
    layout = layout_from_model(MODEL)
    with pytest.raises(ProcessingError, match="at least 3"):
        identify_reflectors(np.zeros((2, 3)), layout)
    rng = np.random.default_rng(1)
    with pytest.raises(ProcessingError, match="do not match the layout"):
        identify_reflectors(rng.uniform(0, 0.5, (6, 3)), layout)

"""A train crossing while deck windows are scanned: found from the points' times, corrected or flagged, never silent."""
from __future__ import annotations

import numpy as np
import pytest

from common.flags import FLAG_MOVED_DURING_SCAN, FLAG_TRANSIENT_REMOVED, code
from lidar.centroid import measure_windows
from lidar.scan import Scan
from lidar.simulate.bridge import BridgeModel
from lidar.simulate.effects import DeckTransient, VisitTiming
from lidar.simulate.epochs import plan_from_truth
from lidar.simulate.scene import BridgeScene, EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.transients import window_motion

MODEL = BridgeModel()
SETUP = ScannerSetup((14.0, -12.0, 1.5), heading_deg=30.0)
TIMING = VisitTiming(duration="lines")


def _visit(where: tuple[float, float] | None, amplitude_m: float = -0.003, *, seed: int = 2,
           model: BridgeModel = MODEL, setup: ScannerSetup = SETUP):
    """Every window scanned in turn; a load crossing during ``where`` (start, length as shares) of M1, M3, M5's."""
    quiet = BridgeScene(model, EpochConditions(timing=TIMING), setup)
    plan = plan_from_truth(quiet, rng=np.random.default_rng(1))
    starts, t = {}, 0.0
    for r in plan.rois:
        starts[r.reflector] = (t, t + quiet.scan_seconds(r.window))
        t = starts[r.reflector][1] + 30.0
    transient = None
    if where is not None:
        hit = [starts[k] for k in ("M1", "M3", "M5")]
        transient = DeckTransient(tuple(a + where[0] * (b - a) for a, b in hit),
                                  tuple(where[1] * (b - a) for a, b in hit), (amplitude_m,) * 3, wobble=0.2)
    scene = BridgeScene(model, EpochConditions(timing=TIMING, transient=transient), setup)
    rng = np.random.default_rng(seed)
    fine = Scan.concatenate([scene.scan(r.window, rng=rng, start_s=starts[r.reflector][0])[0] for r in plan.rois])
    cents, _ = measure_windows(fine.xyz_socs, np.asarray(fine.intensity), plan.rois, time_s=fine.time_s)
    return cents, scene.truth()


def _errors(cents, truth):
    out = {}
    for k, c in cents.items():
        e = np.asarray(c.xyz_socs) - np.asarray(truth.target(k).centre_socs_m)
        out[k] = (abs(e[2]), float(np.sqrt(c.cov[2, 2])))
    return out


def test_a_window_without_movement_says_nothing():
    cents, _ = _visit(None)
    assert not [f for c in cents.values() for f in c.flags if code(f) in (FLAG_MOVED_DURING_SCAN,
                                                                          FLAG_TRANSIENT_REMOVED)]


@pytest.mark.parametrize("where, amplitude", [((0.05, 0.2), -0.003), ((0.45, 0.06), -0.002), ((0.40, 0.2), -0.001),
                                              ((0.35, 0.3), -0.003)])
def test_a_train_during_deck_windows_is_corrected_or_flagged_never_silent(where, amplitude):
    cents, truth = _visit(where, amplitude)
    for k, (err, sigma) in _errors(cents, truth).items():
        flagged = any(code(f) in (FLAG_MOVED_DURING_SCAN, FLAG_TRANSIENT_REMOVED) for f in cents[k].flags)
        if k in ("M2", "M4") or k.startswith("R"):  # no train while they were scanned
            assert not flagged, (k, cents[k].flags)
        assert err <= max(3 * sigma, 0.0002) or any(code(f) == FLAG_MOVED_DURING_SCAN for f in cents[k].flags), \
            (k, err, sigma, cents[k].flags)


def test_window_motion_needs_times_and_a_background():
    pts = np.random.default_rng(0).normal(0, 1, (100, 3)) + [20.0, 0, 0]
    assert not window_motion(pts, np.full(100, np.nan)).checked
    assert not window_motion(pts, np.arange(100.0)).checked  # too few background points to look

"""Terrestrial-scanner simulation of a bridge with ground truth (for tests and the demo).

Typical use::

    from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup, BridgeScene
    scene = BridgeScene(BridgeModel(), EpochConditions(midspan_displacement_m=-0.004),
                        ScannerSetup((20, -12, 1.5), heading_deg=30))
    coarse, truth = scene.scan(scene.coarse_window(), rng=np.random.default_rng(1))

Multi-span bridges (``BridgeModel(spans_m=...)``), deck strain, the atmosphere's range scale (changing during
the visit too), range walk on retro-reflectors (one target's own too), clipped intensities, drift (a sudden jump
too), point times, the instrument's axis and range zero errors and its intensity model (raw amplitude with a
receiver ceiling, a dB scale) are in :class:`EpochConditions` and
:mod:`lidar.simulate.effects`, all off by default; whole visits as files in :mod:`lidar.simulate.files`, campaigns
of them in :mod:`lidar.simulate.campaign`.
"""
from lidar.simulate.bridge import BridgeModel, Target
from lidar.simulate.effects import (
    AxisErrors,
    DriftModel,
    ExponentialStrengthWalk,
    IntensityModel,
    InverseSquareWalk,
    LinearIncidenceWalk,
    LogisticStrengthWalk,
    StrengthStepWalk,
    VisitTiming,
)
from lidar.simulate.scene import BridgeScene, EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth, TargetTruth, WindowTruth

__all__ = ["BridgeModel", "Target", "BridgeScene", "EpochConditions", "ScannerSetup", "ScanTruth", "TargetTruth",
           "WindowTruth", "DriftModel", "VisitTiming", "LinearIncidenceWalk", "InverseSquareWalk", "StrengthStepWalk",
           "LogisticStrengthWalk", "ExponentialStrengthWalk", "AxisErrors", "IntensityModel"]

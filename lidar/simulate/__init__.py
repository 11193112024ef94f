"""Terrestrial-scanner simulation of a bridge with ground truth (for tests and the demo).

Typical use::

    from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup, BridgeScene
    scene = BridgeScene(BridgeModel(), EpochConditions(midspan_displacement_m=-0.004),
                        ScannerSetup((20, -12, 1.5), heading_deg=30))
    coarse, truth = scene.scan(scene.coarse_window(), rng=np.random.default_rng(1))
"""
from lidar.simulate.bridge import BridgeModel, Target
from lidar.simulate.scene import BridgeScene, EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth, TargetTruth

__all__ = ["BridgeModel", "Target", "BridgeScene", "EpochConditions", "ScannerSetup", "ScanTruth", "TargetTruth"]

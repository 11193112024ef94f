"""Simulated epochs for the pipeline tests: see :mod:`lidar.simulate.epochs`."""
from lidar.simulate.epochs import GROUPS, LAB_LOADS_MM, LAB_POSITIONS, MODEL, fine_epoch, plan_from_truth  # noqa: F401

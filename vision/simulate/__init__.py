"""A synthetic dual-camera rig with known target displacements and camera motions (tests, demo, studies)."""
from vision.simulate.motions import calibration_motions, random_motions, table10_schedule
from vision.simulate.rig import Checkerboard, RigGeometry, SyntheticRig

__all__ = ["Checkerboard", "RigGeometry", "SyntheticRig", "calibration_motions", "random_motions",
           "table10_schedule"]

"""Camera-body motion schedules, as 4x4 poses of the rig in its initial sub-camera frame CS(1).

Frame 1 is always the identity: motions are relative to the initial position.
"""
from __future__ import annotations

import numpy as np

from vision.geometry import rigid_from_rotvec


def _triangle(n: int) -> np.ndarray:
    """0 -> +1 -> -1 -> 0 over n samples (a slow sweep through the whole range)."""
    s = np.linspace(0.0, 1.0, n)
    return np.interp(s, [0.0, 0.25, 0.75, 1.0], [0.0, 1.0, -1.0, 0.0])


def table10_schedule(*, frames_per_block: int = 100, rotation_rad: float = 1e-3, translation_m: float = 0.01,
                     rng: np.random.Generator | None = None) -> np.ndarray:
    """The dissertation's motion table: sweeps about and along each axis of CS(1), then random 6-DOF.

    Blocks of ``frames_per_block`` frames: rotation about x, y, z (within +-``rotation_rad``),
    translation along x, y, z (within +-``translation_m``), then uniformly random rotations and
    translations within the same bounds.

    Returns
    -------
    poses : (7 * frames_per_block, 4, 4) float64
        Rig pose at each frame (body -> CS(1)); ``poses[0]`` is the identity.
    """
    rng = rng or np.random.default_rng(0)
    n = frames_per_block
    ramp = _triangle(n)
    rot = np.zeros((7 * n, 3))
    tra = np.zeros((7 * n, 3))
    for axis in range(3):
        rot[axis * n:(axis + 1) * n, axis] = rotation_rad * ramp
        tra[(3 + axis) * n:(4 + axis) * n, axis] = translation_m * ramp
    rot[6 * n:] = rng.uniform(-rotation_rad, rotation_rad, (n, 3))
    tra[6 * n:] = rng.uniform(-translation_m, translation_m, (n, 3))
    return np.stack([rigid_from_rotvec(r, t) for r, t in zip(rot, tra, strict=False)])


def random_motions(n: int, *, rotation_rad: float, translation_m: float,
                   rng: np.random.Generator | None = None) -> np.ndarray:
    """``n`` poses: the identity first, then uniformly random 6-DOF motions within the bounds."""
    rng = rng or np.random.default_rng(0)
    rot = rng.uniform(-rotation_rad, rotation_rad, (n, 3))
    tra = rng.uniform(-translation_m, translation_m, (n, 3))
    rot[0] = 0.0
    tra[0] = 0.0
    return np.stack([rigid_from_rotvec(r, t) for r, t in zip(rot, tra, strict=False)])


def calibration_motions(h: int = 21, *, rotation_rad: float = 2e-3, translation_m: float = 0.005,
                        rng: np.random.Generator | None = None) -> np.ndarray:
    """The rig moved ``h`` times with both targets still (as with the lab's pan-tilt head); frame 1 = rest."""
    return random_motions(h + 1, rotation_rad=rotation_rad, translation_m=translation_m, rng=rng)


def pan_tilt_drift(n: int, *, pan_rad: float = 4.0e-3, tilt_rad: float = 1.0e-3, roll_rad: float = 0.5e-3,
                   translation_m: float = 0.002) -> np.ndarray:
    """Stepwise drift of a rig on a pan-tilt head (the lab's long-term motion).

    Mostly pan (about the vertical y axis), some tilt and roll, and small translations; reaches the bounds at the end.
    """
    steps = np.floor(np.linspace(0, 10, n)) / 10.0
    rot = np.array([tilt_rad, pan_rad, roll_rad])
    tra = np.array([translation_m, -translation_m / 2, translation_m])
    return np.stack([rigid_from_rotvec(s * rot, s * tra) for s in steps])

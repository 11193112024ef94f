"""Where and how a scanner stands for one visit."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from common.errors import InputError


@dataclass(frozen=True)
class ScannerSetup:
    """Scanner position and orientation in the bridge frame.

    The scanner frame (SOCS) is the bridge frame rotated by ``heading_deg``
    about z, then tilted by small ``pitch_deg`` (about y) and ``roll_deg``
    (about x), with its origin at ``position_m``.
    """

    position_m: tuple[float, ...]
    heading_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0

    def __post_init__(self) -> None:
        vals = (*self.position_m, self.heading_deg, self.pitch_deg, self.roll_deg)
        if len(self.position_m) != 3 or not np.all(np.isfinite(vals)):
            raise InputError(f"scanner set-up must be finite, got {vals}")
        object.__setattr__(self, "position_m", tuple(float(v) for v in self.position_m))

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) rotation taking SOCS vectors into the bridge frame."""
        return Rotation.from_euler("ZYX", [self.heading_deg, self.pitch_deg, self.roll_deg], degrees=True).as_matrix()

    @property
    def pose(self) -> np.ndarray:
        """(4, 4) homogeneous transform SOCS -> bridge frame."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.position_m
        return m

    def to_socs(self, xyz_bridge: np.ndarray) -> np.ndarray:
        """Bridge-frame points (N, 3) into this set-up's scanner frame."""
        return (np.asarray(xyz_bridge, dtype=np.float64) - np.asarray(self.position_m)) @ self.rotation

    @classmethod
    def random(cls, rng: np.random.Generator, *, span_m: float = 40.0, x_range: tuple[float, float] = (0.15, 0.85),
               y_range_m: tuple[float, float] = (-20.0, -10.0), height_m: tuple[float, float] = (1.2, 1.8),
               tilt_deg: float = 0.05) -> ScannerSetup:
        """A plausible weekly set-up on the access side of the bridge."""
        return cls(
            position_m=(rng.uniform(*x_range) * span_m, rng.uniform(*y_range_m), rng.uniform(*height_m)),
            heading_deg=rng.uniform(0.0, 360.0),
            pitch_deg=rng.normal(0.0, tilt_deg),
            roll_deg=rng.normal(0.0, tilt_deg),
        )

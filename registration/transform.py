"""A rigid (or similarity) transform between two scanner frames, with its uncertainty and provenance."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True, eq=False)
class Transform:
    """``x_to = scale * R @ x_from + t`` between two frames.

    Attributes
    ----------
    rotation : (3, 3) float64 array
    translation : (3,) float64 array, metres
    scale : float
        1 for a rigid transform.
    source_frame, target_frame : str
        Names of the frames, e.g. ``"socs:2026-03-09"`` and ``"campaign"``.
    sigma_translation_m : float
        Standard deviation of the translation at the tie points' centroid (per axis), metres.
    sigma_rotation_deg : float
        Standard deviation of the rotation angle, degrees.
    method : str
        How it was obtained (``"targets"``, ``"targets+icp"``, ``"identity"``).
    """

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0
    source_frame: str = ""
    target_frame: str = ""
    sigma_translation_m: float = float("nan")
    sigma_rotation_deg: float = float("nan")
    method: str = ""
    notes: tuple[str, ...] = field(default=())

    @classmethod
    def identity(cls, frame: str = "") -> "Transform":
        return cls(np.eye(3), np.zeros(3), 1.0, frame, frame, 0.0, 0.0, "identity")

    @classmethod
    def from_matrix(cls, m: np.ndarray, **kw) -> "Transform":
        m = np.asarray(m, dtype=np.float64)
        s = float(np.cbrt(np.linalg.det(m[:3, :3])))
        return cls(m[:3, :3] / s, m[:3, 3].copy(), s, **kw)

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous matrix."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m

    def apply(self, xyz: np.ndarray) -> np.ndarray:
        """Points (N, 3) of the source frame in the target frame (float64)."""
        return self.scale * (np.asarray(xyz, dtype=np.float64) @ self.rotation.T) + self.translation

    def then(self, other: "Transform") -> "Transform":
        """This transform followed by ``other``."""
        m = other.matrix @ self.matrix
        sig_t = float(np.hypot(np.nan_to_num(self.sigma_translation_m), np.nan_to_num(other.sigma_translation_m)))
        sig_r = float(np.hypot(np.nan_to_num(self.sigma_rotation_deg), np.nan_to_num(other.sigma_rotation_deg)))
        return Transform.from_matrix(m, source_frame=self.source_frame, target_frame=other.target_frame,
                                     sigma_translation_m=sig_t, sigma_rotation_deg=sig_r,
                                     method="+".join(m for m in (self.method, other.method) if m), notes=self.notes + other.notes)

    def inverse(self) -> "Transform":
        r = self.rotation.T
        return Transform(r, -(r @ self.translation) / self.scale, 1.0 / self.scale, self.target_frame,
                         self.source_frame, self.sigma_translation_m, self.sigma_rotation_deg, self.method, self.notes)

    def rotation_angle_deg(self) -> float:
        return float(np.degrees(Rotation.from_matrix(self.rotation).magnitude()))

    def to_json(self) -> dict:
        return {"matrix": self.matrix.tolist(), "scale": self.scale, "source_frame": self.source_frame,
                "target_frame": self.target_frame, "sigma_translation_m": self.sigma_translation_m,
                "sigma_rotation_deg": self.sigma_rotation_deg, "method": self.method, "notes": list(self.notes)}

    @classmethod
    def from_json(cls, d: dict) -> "Transform":
        return cls.from_matrix(np.array(d["matrix"]), source_frame=d.get("source_frame", ""),
                               target_frame=d.get("target_frame", ""),
                               sigma_translation_m=float(d.get("sigma_translation_m", float("nan"))),
                               sigma_rotation_deg=float(d.get("sigma_rotation_deg", float("nan"))),
                               method=d.get("method", ""), notes=tuple(d.get("notes", ())))


def pose_difference(a: Transform, b: Transform) -> tuple[float, float]:
    """(translation difference in metres, rotation difference in degrees) between two transforms."""
    d = np.linalg.inv(a.matrix) @ b.matrix
    return float(np.linalg.norm(d[:3, 3])), float(np.degrees(Rotation.from_matrix(d[:3, :3] /
                                                                                  np.cbrt(np.linalg.det(d[:3, :3])))
                                                                 .magnitude()))

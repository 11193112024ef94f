"""Rigid motions and camera projections used by the dual-camera method.

Conventions
-----------
* A rigid transform is a 4x4 homogeneous matrix ``B`` mapping coordinates in one frame to
  coordinates in another: ``x_to = B @ [x_from, 1]``. Names say the direction, e.g.
  ``B_ws_to_cs`` maps sub-target coordinates (WS) to sub-camera coordinates (CS).
* Camera frames: x right, y down, z along the optical axis; image coordinates are (u, v) in
  pixels with the origin at the top-left pixel's top-left corner, u to the right, v down.
  Arrays of image points are ``(..., 2)`` as (u, v); image *arrays* are indexed (row, col).
* Lengths are metres, angles radians.
"""
from __future__ import annotations

import numpy as np

from common.rigid import apply_matrix, invert_matrix, matrix_from_rotvec, matrix_from_rt

# The 4x4 form of common.rigid.Transform, under the names this module's callers use.
rigid = matrix_from_rt
rigid_from_rotvec = matrix_from_rotvec
invert = invert_matrix
apply = apply_matrix


def project_pinhole(K: np.ndarray, xyz_cam: np.ndarray) -> np.ndarray:
    """Project camera-frame points (..., 3) with the 3x3 intrinsic matrix ``K`` to (u, v) pixels.

    ``K`` follows OpenCV: pixel centres sit at integer coordinates, so a point on the optical
    axis lands on (cx, cy).
    """
    xyz_cam = np.asarray(xyz_cam, dtype=float)
    z = xyz_cam[..., 2]
    if np.any(z <= 0):
        raise ValueError("a point is behind the camera")
    x = xyz_cam[..., 0] / z
    y = xyz_cam[..., 1] / z
    u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
    v = K[1, 1] * y + K[1, 2]
    return np.stack([u, v], axis=-1)


def intrinsic_matrix(focal_px: float, width_px: int, height_px: int) -> np.ndarray:
    """Square-pixel intrinsic matrix with the principal point at the image centre."""
    return np.array([[focal_px, 0.0, (width_px - 1) / 2.0],
                     [0.0, focal_px, (height_px - 1) / 2.0],
                     [0.0, 0.0, 1.0]])


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) of one 3x3 rotation or a stack (n, 3, 3)."""
    tr = np.trace(np.asarray(R), axis1=-2, axis2=-1)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))

"""Rigid (and similarity) transforms.

The one :class:`Transform` type that lidar, registration and vision share, its 4x4 matrix form, and the least-squares
fit between matched point sets.

Conventions: a transform maps coordinates of a source frame to a target frame,
``x_to = scale * R @ x_from + t``; its :attr:`Transform.matrix` is the 4x4 homogeneous form
``x_to = M @ [x_from, 1]``. Numeric code that works on stacks of poses (the dual-camera calibration)
uses the matrix helpers :func:`matrix_from_rt`, :func:`matrix_from_rotvec`, :func:`invert_matrix`
and :func:`apply_matrix`, which accept ``(..., 4, 4)`` stacks; :meth:`Transform.from_matrix` and
:attr:`Transform.matrix` move between the two forms. Lengths are metres.

>>> import numpy as np
>>> T = Transform.from_rt(np.eye(3), [1.0, 2.0, 3.0])
>>> T.apply([[0.0, 0.0, 0.0]]).tolist()
[[1.0, 2.0, 3.0]]
>>> T.inverse().then(T).apply([[5.0, 5.0, 5.0]]).round(12).tolist()
[[5.0, 5.0, 5.0]]
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError


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
    def identity(cls, frame: str = "") -> Transform:
        return cls(np.eye(3), np.zeros(3), 1.0, frame, frame, 0.0, 0.0, "identity")

    @classmethod
    def from_rt(cls, rotation: ArrayLike, translation: ArrayLike, **kw: Any) -> Transform:
        """A rigid transform from a (3, 3) rotation and a (3,) translation."""
        return cls(np.asarray(rotation, dtype=np.float64), np.asarray(translation, dtype=np.float64).reshape(3), 1.0,
                   **kw)

    @classmethod
    def from_matrix(cls, m: np.ndarray, **kw: Any) -> Transform:
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

    def then(self, other: Transform) -> Transform:
        """The transform that applies this one, then ``other``."""
        m = other.matrix @ self.matrix
        sig_t = float(np.hypot(np.nan_to_num(self.sigma_translation_m), np.nan_to_num(other.sigma_translation_m)))
        sig_r = float(np.hypot(np.nan_to_num(self.sigma_rotation_deg), np.nan_to_num(other.sigma_rotation_deg)))
        return Transform.from_matrix(m, source_frame=self.source_frame, target_frame=other.target_frame,
                                     sigma_translation_m=sig_t, sigma_rotation_deg=sig_r,
                                     method="+".join(m for m in (self.method, other.method) if m),
                                     notes=self.notes + other.notes)

    def inverse(self) -> Transform:
        r = self.rotation.T
        return Transform(r, -(r @ self.translation) / self.scale, 1.0 / self.scale, self.target_frame,
                         self.source_frame, self.sigma_translation_m, self.sigma_rotation_deg, self.method, self.notes)

    def rotation_angle_deg(self) -> float:
        # local: scipy.spatial: 0.07-0.09 s of scanners' and reflector list's start-up (measured)
        from scipy.spatial.transform import Rotation

        return float(np.degrees(Rotation.from_matrix(self.rotation).magnitude()))

    def to_json(self) -> dict:
        return {"matrix": self.matrix.tolist(), "scale": self.scale, "source_frame": self.source_frame,
                "target_frame": self.target_frame, "sigma_translation_m": self.sigma_translation_m,
                "sigma_rotation_deg": self.sigma_rotation_deg, "method": self.method, "notes": list(self.notes)}

    @classmethod
    def from_json(cls, d: dict) -> Transform:
        return cls.from_matrix(np.array(d["matrix"]), source_frame=d.get("source_frame", ""),
                               target_frame=d.get("target_frame", ""),
                               sigma_translation_m=float(d.get("sigma_translation_m", float("nan"))),
                               sigma_rotation_deg=float(d.get("sigma_rotation_deg", float("nan"))),
                               method=d.get("method", ""), notes=tuple(d.get("notes", ())))


def pose_difference(a: Transform, b: Transform) -> tuple[float, float]:
    """(translation difference in metres, rotation difference in degrees) between two transforms."""
    # local: scipy.spatial: 0.07-0.09 s of scanners' and reflector list's start-up (measured)
    from scipy.spatial.transform import Rotation

    d = np.linalg.inv(a.matrix) @ b.matrix
    return float(np.linalg.norm(d[:3, 3])), float(np.degrees(Rotation.from_matrix(d[:3, :3] /
                                                                                  np.cbrt(np.linalg.det(d[:3, :3])))
                                                                 .magnitude()))


def fit_rigid(src: np.ndarray, dst: np.ndarray, weights: ArrayLike | None = None, **provenance: Any) -> Transform:
    """Least-squares rigid transform with ``dst ~= T.apply(src)`` (Kabsch, no reflection).

    Parameters
    ----------
    src, dst : (N, 3) float64 arrays
        Matched points, N >= 3 not collinear.
    weights : (N,) array, optional
        Relative weights of the pairs (default: equal).
    **provenance
        ``source_frame``, ``target_frame``, ``method``... recorded on the result (default method
        ``"least squares"``).

    Returns
    -------
    Transform
        With ``rotation`` (3, 3) and ``translation`` (3,); scale 1.

    Examples
    --------
    >>> import numpy as np
    >>> src = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> T = fit_rigid(src, src + [0.5, 0.0, -0.25])
    >>> bool(np.allclose(T.translation, [0.5, 0.0, -0.25])), bool(np.allclose(T.rotation, np.eye(3)))
    (True, True)
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or src.shape[0] < 3:
        raise InputError("a rigid fit needs two matched (N, 3) point sets with N >= 3")
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    cs = w @ src
    cd = w @ dst
    h = (src - cs).T @ ((dst - cd) * w[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    provenance.setdefault("method", "least squares")
    return Transform.from_rt(r, cd - r @ cs, **provenance)


def pairwise_distances(xyz: np.ndarray) -> np.ndarray:
    """(N, N) Euclidean distances between the rows of ``xyz`` (N, 3)."""
    diff = xyz[:, None, :] - xyz[None, :, :]
    return np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))


# ---------------------------------------------------------------- 4x4 matrix form (stacks allowed)
def matrix_from_rt(rotation: ArrayLike, translation: ArrayLike) -> np.ndarray:
    """4x4 transform from a 3x3 rotation and a translation of shape (3,)."""
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = np.asarray(translation, dtype=float).reshape(3)
    return m


def skew(v: ArrayLike) -> np.ndarray:
    """Cross-product matrices: ``skew(v) @ w == np.cross(v, w)``, shape (..., 3) -> (..., 3, 3).

    Examples
    --------
    >>> skew([1.0, 2.0, 3.0]) @ np.array([4.0, 5.0, 6.0])
    array([-3.,  6., -3.])
    """
    a = np.asarray(v, dtype=np.float64)
    out = np.zeros(a.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -a[..., 2], a[..., 1], -a[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = a[..., 2], -a[..., 1], a[..., 0]
    return out


def rotations_from_rotvecs(rotvecs: ArrayLike) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 3) rotation vectors (axis * angle, rad), by Rodrigues' formula."""
    w = np.asarray(rotvecs, dtype=np.float64).reshape(-1, 3)
    theta = np.linalg.norm(w, axis=1)
    k = skew(w / np.maximum(theta, 1e-300)[:, None])
    s, c = np.sin(theta)[:, None, None], (1.0 - np.cos(theta))[:, None, None]
    return np.eye(3)[None] + s * k + c * (k @ k)


def rotate_vectors(v: ArrayLike, rotvec: ArrayLike) -> np.ndarray:
    """(N, 3) vectors rotated by (N, 3) (or (1, 3)) rotation vectors (axis * angle, rad), by Rodrigues' formula."""
    v = np.asarray(v, dtype=np.float64)
    rotvec = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(rotvec, axis=1, keepdims=True)
    safe = np.where(theta > 0, theta, 1.0)
    k = rotvec / safe
    cos, sin = np.cos(theta), np.sin(theta)
    kxv = np.cross(k, v)
    kdv = np.einsum("ij,ij->i", np.broadcast_to(k, v.shape), v)[:, None]
    return v * cos + kxv * sin + k * kdv * (1.0 - cos)


def rotation_from_rotvec(rotvec: ArrayLike) -> np.ndarray:
    """(3, 3) rotation matrix of a rotation vector (axis * angle, rad), by Rodrigues' formula.

    Plain numpy: the adjustments call it in their inner loops, and importing scipy.spatial for it costs
    every command 0.3 s of start-up.
    """
    w = np.asarray(rotvec, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(w))
    k = skew(w)
    if theta < 1e-15:
        return np.eye(3) + k
    k /= theta
    return np.eye(3) + np.sin(theta) * k + (1.0 - np.cos(theta)) * (k @ k)


def matrix_from_rotvec(rotvec: ArrayLike, translation: ArrayLike) -> np.ndarray:
    """4x4 transform from a rotation vector (axis * angle, rad) and a translation (m)."""
    # local: scipy.spatial: 0.07-0.09 s of scanners' and reflector list's start-up (measured)
    from scipy.spatial.transform import Rotation

    return matrix_from_rt(Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix(), translation)


def invert_matrix(m: np.ndarray) -> np.ndarray:
    """Inverse of one rigid 4x4 transform or a stack of them (n, 4, 4)."""
    m = np.asarray(m, dtype=float)
    r = m[..., :3, :3]
    t = m[..., :3, 3]
    rt = np.swapaxes(r, -1, -2)
    out = np.zeros_like(m)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, t)
    out[..., 3, 3] = 1.0
    return out


def apply_matrix(m: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Transform points ``xyz`` of shape (..., 3) by the 4x4 ``m``."""
    xyz = np.asarray(xyz, dtype=float)
    return xyz @ m[:3, :3].T + m[:3, 3]

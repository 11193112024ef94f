"""A simply supported bridge with retro-reflective targets, as triangle meshes for ray casting.

Bridge frame: x along the span (pier 1 at x = 0, pier 2 at x = span), z up,
ground at z = 0, the access side (where the scanner stands) at y < 0.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError


@dataclass(frozen=True)
class Target:
    """A retro-reflective disc glued to the structure.

    Attributes
    ----------
    id : str
    group : {"reference", "measurement"}
    centre_m : (3,) float tuple
        Centre of the disc in the bridge frame, undeformed, metres.
    normal : (3,) float tuple
        Outward unit normal of the surface it is glued to.
    diameter_m : float
    """

    id: str
    group: str
    centre_m: tuple[float, ...]
    normal: tuple[float, ...]
    diameter_m: float = 0.05

    def __post_init__(self) -> None:
        if self.group not in ("reference", "measurement"):
            raise InputError(f"target {self.id}: group must be 'reference' or 'measurement', not {self.group!r}")
        n = np.asarray(self.normal, dtype=float)
        object.__setattr__(self, "normal", tuple(float(v) for v in n / np.linalg.norm(n)))
        object.__setattr__(self, "centre_m", tuple(float(v) for v in self.centre_m))


def _default_targets(span: float, pier_length: float, deck_bottom: float, diameter: float) -> tuple[Target, ...]:
    """The demo bridge's nine targets.

    Four reference targets on the piers' inner faces (looking into the span, where a scanner between the piers sees
    them at moderate incidence), at two heights and two positions across the
    bridge; five measurement targets under the deck, symmetric about midspan, on two girder lines.
    """
    face1 = pier_length / 2 + 0.001  # pier 1's +x face, 1 mm proud
    face2 = span - pier_length / 2 - 0.001  # pier 2's -x face
    ref = [
        Target("R1", "reference", (face1, -1.5, 2.0), (1, 0, 0), diameter),
        Target("R2", "reference", (face1, 1.5, 5.0), (1, 0, 0), diameter),
        Target("R3", "reference", (face2, 1.5, 2.0), (-1, 0, 0), diameter),
        Target("R4", "reference", (face2, -1.5, 5.0), (-1, 0, 0), diameter),
    ]
    z = deck_bottom - 0.001
    fractions = (0.2, 0.35, 0.5, 0.65, 0.8)
    ys = (-2.0, 1.0, -2.0, 1.0, -2.0)
    meas = [Target(f"M{k + 1}", "measurement", (f * span, y, z), (0, 0, -1), diameter)
            for k, (f, y) in enumerate(zip(fractions, ys))]
    return tuple(ref + meas)


@dataclass(frozen=True)
class BridgeModel:
    """Geometry of the simulated bridge (metres).

    A box-girder deck of ``span_m`` between pier centrelines, overhanging each
    pier by ``overhang_m``, on two rectangular piers, above flat ground.
    """

    span_m: float = 40.0
    deck_width_m: float = 6.0
    deck_bottom_m: float = 7.0
    deck_depth_m: float = 2.0
    overhang_m: float = 1.0
    pier_length_m: float = 2.0
    pier_width_m: float = 5.0
    target_diameter_m: float = 0.05
    targets: tuple[Target, ...] = field(default=())

    def __post_init__(self) -> None:
        if self.span_m <= 0 or self.deck_width_m <= 0 or self.deck_bottom_m <= 0:
            raise InputError("bridge model dimensions must be positive")
        if not self.targets:
            object.__setattr__(self, "targets", _default_targets(
                self.span_m, self.pier_length_m, self.deck_bottom_m, self.target_diameter_m))
        ids = [t.id for t in self.targets]
        if len(set(ids)) != len(ids):
            raise InputError("bridge model: target ids must be unique")

    def target(self, target_id: str) -> Target:
        for t in self.targets:
            if t.id == target_id:
                return t
        raise InputError(f"bridge model has no target {target_id!r}")

    def deflection_m(self, x_m: ArrayLike, midspan_m: float) -> np.ndarray:
        """Vertical displacement (positive up) along the span for a midspan amplitude.

        The first-mode shape of a simply supported beam, ``a sin(pi x / L)``
        between the supports and zero outside them.
        """
        x = np.asarray(x_m, dtype=np.float64)
        w = midspan_m * np.sin(np.pi * x / self.span_m)
        return np.where((x >= 0) & (x <= self.span_m), w, 0.0)

    def with_targets(self, targets: Sequence[Target]) -> "BridgeModel":
        return replace(self, targets=tuple(targets))


def box_mesh(lo: Sequence[float], hi: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and outward triangles (12, 3) of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=np.float64)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], dtype=np.int32)
    return v, f


def deck_mesh(model: BridgeModel, midspan_m: float, stations: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """The deck as a prism with ``stations`` cross-sections along x, deflected vertically."""
    x = np.linspace(-model.overhang_m, model.span_m + model.overhang_m, stations)
    w = model.deflection_m(x, midspan_m)
    hw = model.deck_width_m / 2
    zb, zt = model.deck_bottom_m, model.deck_bottom_m + model.deck_depth_m
    corners = np.array([[-hw, zb], [hw, zb], [hw, zt], [-hw, zt]])  # (y, z) around the section
    v = np.empty((stations, 4, 3))
    v[:, :, 0] = x[:, None]
    v[:, :, 1] = corners[None, :, 0]
    v[:, :, 2] = corners[None, :, 1] + w[:, None]
    verts = v.reshape(-1, 3)
    faces = []
    for s in range(stations - 1):
        for c in range(4):
            a, b = s * 4 + c, s * 4 + (c + 1) % 4
            faces.append([a, a + 4, b])
            faces.append([b, a + 4, b + 4])
    last = (stations - 1) * 4
    faces += [[0, 1, 2], [0, 2, 3], [last, last + 2, last + 1], [last, last + 3, last + 2]]
    return verts, np.asarray(faces, dtype=np.int32)


def pier_meshes(model: BridgeModel) -> list[tuple[np.ndarray, np.ndarray]]:
    """(vertices, triangles) of each pier's box, bridge frame, metres."""
    hl, hw = model.pier_length_m / 2, model.pier_width_m / 2
    return [box_mesh((xc - hl, -hw, 0.0), (xc + hl, hw, model.deck_bottom_m)) for xc in (0.0, model.span_m)]


def ground_mesh(model: BridgeModel, extent_m: float = 150.0) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of a square of ground ``extent_m`` wide centred on the span, bridge frame."""
    xc = model.span_m / 2
    v = np.array([[xc - extent_m, -extent_m, 0], [xc + extent_m, -extent_m, 0],
                  [xc + extent_m, extent_m, 0], [xc - extent_m, extent_m, 0]], dtype=np.float64)
    return v, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def plate_mesh(centre: ArrayLike, normal: ArrayLike, half_size_m: float) -> tuple[np.ndarray, np.ndarray]:
    """A square plate (two-sided) centred on a point, facing ``normal``."""
    e1, e2 = in_plane_axes(normal)
    c = np.asarray(centre, dtype=np.float64)
    v = np.array([c + half_size_m * (sx * e1 + sy * e2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return v, np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], dtype=np.int32)


def in_plane_axes(normal: ArrayLike, up_hint: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane normal to ``normal``.

    The second axis is the projection of +z (or of +y for horizontal planes),
    so on a vertical pier face it points up.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    hint = np.array([0.0, 0.0, 1.0]) if up_hint is None else np.asarray(up_hint, dtype=np.float64)
    if abs(np.dot(hint, n)) > 0.9:
        hint = np.array([0.0, 1.0, 0.0])
    e2 = hint - np.dot(hint, n) * n
    e2 /= np.linalg.norm(e2)
    e1 = np.cross(e2, n)
    return e1, e2

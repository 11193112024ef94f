"""Centroid-level simulation: measured target positions of a bridge of any geometry, with known truth.

Ray-casting whole scans (:mod:`lidar.simulate.scene`) is the end-to-end check;
studying the displacement math over many geometries needs thousands of
epochs, so this module draws each target's centroid directly: the true
position seen from a levelled scanner standing anywhere beside the bridge,
plus a Gaussian error with the covariance a centroid of ``n`` points has (range
noise along the line of sight, angular noise across it).

Bridge frame: x along the span from pier 1 (x = 0) to pier 2 (x = span), y
across, z up, metres.
"""
from __future__ import annotations

from dataclasses import dataclass

from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from lidar.displacement import Observation


@dataclass(frozen=True)
class BridgeGeometry:
    """Where the targets are.

    Attributes
    ----------
    span_m : float
    pier_separation_m : float
        Distance between the two reference targets of one pier (one above the other, 1/3 of it sideways).
    girder_offsets_m : tuple of float
        Transverse positions of the deck target lines (e.g. (-2.4, 1.2) for an asymmetric twin girder).
    stations : tuple of float
        Deck target positions along the span, as fractions of it.
    deck_height_m : float
        Height of the deck targets above the lower pier targets.
    """

    span_m: float = 40.0
    pier_separation_m: float = 1.8
    girder_offsets_m: tuple[float, ...] = (-2.4, 1.2)
    stations: tuple[float, ...] = (0.25, 0.5, 0.75)
    deck_height_m: float = 6.0

    def targets(self) -> tuple[tuple[str, ...], dict[str, str], np.ndarray]:
        """Target ids, their groups and (N, 3) bridge-frame positions."""
        ids, groups, xyz = [], {}, []
        d = self.pier_separation_m
        up = np.array([0.0, 1.0 / 3.0, np.sqrt(8.0) / 3.0]) * d  # mostly up, a third sideways
        for k, x in enumerate((0.0, self.span_m)):
            for j, p in enumerate((np.zeros(3), up)):
                rid = f"R{2 * k + j + 1}"
                ids.append(rid)
                groups[rid] = "reference"
                xyz.append(np.array([x, 0.0, 0.0]) + p)
        n = 1
        for y in self.girder_offsets_m:
            for s in self.stations:
                rid = f"M{n}"
                n += 1
                ids.append(rid)
                groups[rid] = "measurement"
                xyz.append([s * self.span_m, y, self.deck_height_m])
        return tuple(ids), groups, np.array(xyz, dtype=np.float64)


def deflection(xyz: np.ndarray, groups: dict[str, str], ids: Sequence[str], geometry: BridgeGeometry, *,
               midspan_m: float,
               girder_ratio: float = 1.0, asymmetry_m: float = 0.0) -> np.ndarray:
    """Vertical deck displacement (m, positive up) of each target; reference targets do not move.

    A half-sine sag of ``midspan_m`` at midspan on the first girder line,
    ``girder_ratio`` times that on the others (a torsion of the cross-section
    when it is not 1), plus a full-sine ``asymmetry_m`` (an off-centre load).
    """
    out = np.zeros(len(ids))
    first = geometry.girder_offsets_m[0]
    for k, rid in enumerate(ids):
        if groups[rid] != "measurement":
            continue
        x, y = xyz[k, 0] / geometry.span_m, xyz[k, 1]
        scale = 1.0 if y == first else girder_ratio
        out[k] = midspan_m * scale * np.sin(np.pi * x) + asymmetry_m * np.sin(2 * np.pi * x)
    return out


def observe(xyz_bridge: np.ndarray, ids: Sequence[str], *, scanner_xyz: ArrayLike, heading_deg: float,
            rng: np.random.Generator,
            range_sigma_m: float = 0.005, angle_sigma_rad: float = 4e-5, points: int = 1000,
            tilt_deg: float = 0.005, return_rotation: bool = False) -> dict | tuple[dict, np.ndarray]:
    """Centroids of the targets as a scanner at ``scanner_xyz`` (bridge frame) would measure them.

    Returns observations in the scanner's own frame (levelled to ``tilt_deg``,
    turned by ``heading_deg``), each with the covariance of a centroid of
    ``points`` points: ``range_sigma_m**2 / points`` along the line of sight and
    ``(angle_sigma_rad * range)**2 / points`` across it. With
    ``return_rotation`` also the scanner's rotation (bridge = socs @ R.T + scanner_xyz).
    """
    tilt = rng.normal(0.0, tilt_deg, 2)
    rot = Rotation.from_euler("zyx", [heading_deg, tilt[0], tilt[1]], degrees=True).as_matrix()
    socs = (xyz_bridge - np.asarray(scanner_xyz, dtype=np.float64)) @ rot  # bridge -> scanner frame
    out = {}
    for k, rid in enumerate(ids):
        p = socs[k]
        r = float(np.linalg.norm(p))
        los = p / r
        cov = (range_sigma_m ** 2 / points) * np.outer(los, los) + \
            ((angle_sigma_rad * r) ** 2 / points) * (np.eye(3) - np.outer(los, los))
        out[rid] = Observation(p + rng.multivariate_normal(np.zeros(3), cov), cov)
    return (out, rot) if return_rotation else out


def random_station(geometry: BridgeGeometry, rng: np.random.Generator, *, height_m: float = 1.5) -> np.ndarray:
    """A scanner position beside the bridge: 20-80 % along the span, 8-20 m to one side."""
    side = rng.choice([-1.0, 1.0])
    return np.array([rng.uniform(0.2, 0.8) * geometry.span_m, side * rng.uniform(8.0, 20.0), height_m])

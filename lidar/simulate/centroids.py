"""Centroid-level simulation: measured target positions of a bridge of any geometry, with known truth.

Ray-casting whole scans (:mod:`lidar.simulate.scene`) is the end-to-end check;
studying the displacement math over many geometries needs thousands of
epochs, so this module draws each target's centroid directly: the true
position seen from a levelled scanner standing anywhere beside the bridge,
plus a Gaussian error with the covariance a centroid of ``n`` points has (range
noise along the line of sight, angular noise across it).

Bridge frame: x along the span from pier 1 (x = 0) to the last pier (x = the
sum of the spans), y across, z up, metres.

The scanner's systematic errors of :mod:`lidar.simulate.effects` are
available here too, all off by default: the atmosphere's range scale, a
range walk along each target's line of sight, and the instrument's drift (a
time per target), so estimators can be tried on thousands of epochs in
milliseconds.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from common.errors import InputError
from lidar.displacement import Observation
from lidar.simulate.effects import DriftModel, RangeWalk, return_strength


@dataclass(frozen=True)
class BridgeGeometry:
    """Where the targets are.

    Attributes
    ----------
    span_m : float
        Distance between the end piers (set from ``spans_m`` when given). Default 40 m.
    pier_separation_m : float
        Distance between the two reference targets of one end pier (one above the other, 1/3 of it sideways).
    girder_offsets_m : tuple of float
        Transverse positions of the deck target lines (e.g. (-2.4, 1.2) for an asymmetric twin girder).
    stations : tuple of float
        Deck target positions along each span, as fractions of it.
    deck_height_m : float
        Height of the deck targets above the lower pier targets.
    spans_m : tuple of float
        Span lengths, e.g. (39.9, 39.9, 39.9). Default (empty): one span of ``span_m``.
    pier_length_m : float
        Length of an inner pier along x: its two targets (one on each face, the -x one
        ``pier_separation_m`` higher) are this far apart along x. Default 2 m.

    Target ids: R1, R2 on the first pier, then two per inner pier (-x face, +x face), then two on the last
    pier, in order along x; M1.. span by span, in each girder line by girder line, along x.
    """

    span_m: float = 40.0
    pier_separation_m: float = 1.8
    girder_offsets_m: tuple[float, ...] = (-2.4, 1.2)
    stations: tuple[float, ...] = (0.25, 0.5, 0.75)
    deck_height_m: float = 6.0
    spans_m: tuple[float, ...] = ()
    pier_length_m: float = 2.0

    def __post_init__(self) -> None:
        spans = tuple(float(v) for v in self.spans_m) or (float(self.span_m),)
        if min(spans) <= 0 or not all(np.isfinite(spans)):
            raise InputError(f"bridge geometry: spans must be positive, got {spans}")
        object.__setattr__(self, "spans_m", spans)
        object.__setattr__(self, "span_m", float(sum(spans)) if len(spans) > 1 else spans[0])

    @property
    def support_x_m(self) -> np.ndarray:
        """(n_spans + 1,) x of every support, metres."""
        return np.concatenate([[0.0], np.cumsum(self.spans_m)])

    def _reference(self) -> list[np.ndarray]:
        up = np.array([0.0, 1.0 / 3.0, np.sqrt(8.0) / 3.0]) * self.pier_separation_m  # mostly up, a third sideways
        xs = self.support_x_m
        out = [np.array([0.0, 0.0, 0.0]), up.copy()]
        half = self.pier_length_m / 2
        for x in xs[1:-1]:
            out += [np.array([x - half, 0.0, 0.0]) + up, np.array([x + half, 0.0, 0.0])]
        return out + [np.array([xs[-1], 0.0, 0.0]), np.array([xs[-1], 0.0, 0.0]) + up]

    def targets(self) -> tuple[tuple[str, ...], dict[str, str], np.ndarray]:
        """Target ids, their groups and (N, 3) bridge-frame positions."""
        ids: list[str] = []
        groups: dict[str, str] = {}
        xyz: list = []
        for k, p in enumerate(self._reference()):
            rid = f"R{k + 1}"
            ids.append(rid)
            groups[rid] = "reference"
            xyz.append(p)
        n = 1
        for x0, span in zip(self.support_x_m[:-1], self.spans_m, strict=False):
            for y in self.girder_offsets_m:
                for s in self.stations:
                    rid = f"M{n}"
                    n += 1
                    ids.append(rid)
                    groups[rid] = "measurement"
                    xyz.append([x0 + s * span if len(self.spans_m) > 1 else s * self.span_m, y,
                                self.deck_height_m])
        return tuple(ids), groups, np.array(xyz, dtype=np.float64)

    def normals(self) -> np.ndarray:
        """(N, 3) outward unit normal of every target, in :meth:`targets` order.

        Reference targets face along the axis into the adjoining span (the first pier's +x, the last pier's -x,
        an inner pier's two faces -x and +x); deck targets face down.
        """
        n_inner = len(self.spans_m) - 1
        ref = [(1.0, 0, 0)] * 2 + [(-1.0, 0, 0), (1.0, 0, 0)] * n_inner + [(-1.0, 0, 0)] * 2
        deck = [(0, 0, -1.0)] * (len(self.spans_m) * len(self.girder_offsets_m) * len(self.stations))
        return np.array(ref + deck, dtype=np.float64)


def deflection(xyz: np.ndarray, groups: dict[str, str], ids: Sequence[str], geometry: BridgeGeometry, *,
               midspan_m: float,
               girder_ratio: float = 1.0, asymmetry_m: float = 0.0,
               span_amplitudes_m: Sequence[float] | None = None) -> np.ndarray:
    """Vertical deck displacement (m, positive up) of each target; reference targets do not move.

    A half-sine sag of ``midspan_m`` at midspan (of every span; ``span_amplitudes_m`` gives one per span
    instead) on the first girder line, ``girder_ratio`` times that on the others (a torsion of the
    cross-section when it is not 1), plus a full-sine ``asymmetry_m`` in each span (an off-centre load).
    """
    out = np.zeros(len(ids))
    first = geometry.girder_offsets_m[0]
    starts = geometry.support_x_m
    amps = np.full(len(geometry.spans_m), midspan_m) if span_amplitudes_m is None else \
        np.asarray(span_amplitudes_m, dtype=np.float64)
    if amps.shape != (len(geometry.spans_m),):
        raise InputError(f"{len(geometry.spans_m)} spans but {amps.size} span amplitudes")
    for k, rid in enumerate(ids):
        if groups[rid] != "measurement":
            continue
        if len(geometry.spans_m) == 1 and span_amplitudes_m is None:
            x, a = xyz[k, 0] / geometry.span_m, midspan_m
        else:
            j = int(np.clip(np.searchsorted(starts, xyz[k, 0], side="right") - 1, 0, len(geometry.spans_m) - 1))
            x, a = (xyz[k, 0] - starts[j]) / geometry.spans_m[j], float(amps[j])
        y = xyz[k, 1]
        scale = 1.0 if y == first else girder_ratio
        out[k] = a * scale * np.sin(np.pi * x) + asymmetry_m * np.sin(2 * np.pi * x)
    return out


def along_span(xyz: np.ndarray, groups: dict[str, str], ids: Sequence[str], *, strain: float,
               fixed_x_m: float = 0.0) -> np.ndarray:
    """(N,) movement along x (m) of each target under a deck strain: ``strain * (x - fixed_x_m)`` on the deck.

    Reference (pier) targets do not move. ``fixed_x_m`` is the fixed bearing's x, default the first pier.
    """
    out = np.zeros(len(ids))
    for k, rid in enumerate(ids):
        if groups[rid] == "measurement":
            out[k] = strain * (xyz[k, 0] - fixed_x_m)
    return out


def observe(xyz_bridge: np.ndarray, ids: Sequence[str], *, scanner_xyz: ArrayLike, heading_deg: float,
            rng: np.random.Generator,
            range_sigma_m: float = 0.005, angle_sigma_rad: float = 4e-5, points: int = 1000,
            tilt_deg: float = 0.005, return_rotation: bool = False, range_scale_ppm: float = 0.0,
            range_walk: RangeWalk | None = None, normals_bridge: np.ndarray | None = None,
            drift: DriftModel | None = None, times_s: ArrayLike | None = None) -> dict | tuple[dict, np.ndarray]:
    """Centroids of the targets as a scanner at ``scanner_xyz`` (bridge frame) would measure them.

    Returns observations in the scanner's own frame (levelled to ``tilt_deg``,
    turned by ``heading_deg``), each with the covariance of a centroid of
    ``points`` points: ``range_sigma_m**2 / points`` along the line of sight and
    ``(angle_sigma_rad * range)**2 / points`` across it. With
    ``return_rotation`` also the scanner's rotation (bridge = socs @ R.T + scanner_xyz)
    at the start of the visit.

    Systematic errors, all off by default and drawing no random numbers:

    - ``drift`` with ``times_s`` ((N,) seconds since the visit started, when each target was scanned): the
      target is reported in the instrument's frame of that moment (:class:`~lidar.simulate.effects.DriftModel`).
    - ``range_walk``: the range reads short by ``range_walk.bias_m(range, cos incidence, strength)`` along the
      line of sight; the incidence from ``normals_bridge`` ((N, 3) outward normals, bridge frame; without them
      head-on), the strength a full disc's (:func:`~lidar.simulate.effects.return_strength`).
    - ``range_scale_ppm``: every range times ``1 + ppm * 1e-6`` (the atmosphere).
    """
    tilt = rng.normal(0.0, tilt_deg, 2)
    rot = Rotation.from_euler("zyx", [heading_deg, tilt[0], tilt[1]], degrees=True).as_matrix()
    socs = (xyz_bridge - np.asarray(scanner_xyz, dtype=np.float64)) @ rot  # bridge -> scanner frame
    if drift is not None or range_walk is not None or range_scale_ppm:
        socs = _systematic(socs, rot, range_scale_ppm=range_scale_ppm, range_walk=range_walk,
                           normals_bridge=normals_bridge, drift=drift, times_s=times_s)
    out = {}
    for k, rid in enumerate(ids):
        p = socs[k]
        r = float(np.linalg.norm(p))
        los = p / r
        across = _across(los)
        sd_range, sd_across = range_sigma_m / np.sqrt(points), angle_sigma_rad * r / np.sqrt(points)
        cov = sd_range ** 2 * np.outer(los, los) + sd_across ** 2 * (np.eye(3) - np.outer(los, los))
        z = rng.standard_normal(3)
        out[rid] = Observation(p + sd_range * z[0] * los + sd_across * (z[1] * across[0] + z[2] * across[1]), cov)
    return (out, rot) if return_rotation else out


def _across(los: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal directions across a unit line of sight, from a fixed rule.

    The noise is drawn along these rather than by ``Generator.multivariate_normal``, whose SVD picks arbitrary
    axes in the covariance's two equal across-beam eigenvalues: which axes depends on the LAPACK kernel, so
    the same seed gave centroids 80 um apart on two CPUs.
    """
    ref = np.array([0.0, 0.0, 1.0]) if abs(los[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = np.cross(los, ref)
    a /= np.linalg.norm(a)
    return np.stack([a, np.cross(los, a)])


def _systematic(socs: np.ndarray, rot: np.ndarray, *, range_scale_ppm: float, range_walk: RangeWalk | None,
                normals_bridge: np.ndarray | None, drift: DriftModel | None,
                times_s: ArrayLike | None) -> np.ndarray:
    """(N, 3) true scanner-frame positions as the instrument reports them: drift, then range walk and scale."""
    if drift is not None:
        if times_s is None:
            raise InputError("a drift needs the time each target was scanned (times_s)")
        t = np.asarray(times_s, dtype=np.float64)
        if t.shape != (len(socs),):
            raise InputError(f"times_s must hold one time per target ({len(socs)}), got shape {t.shape}")
        socs = drift.to_current(socs, t)
    r = np.linalg.norm(socs, axis=1)
    new_r = r.copy()
    if range_walk is not None:
        if normals_bridge is None:
            cos_inc = np.ones(len(socs))
        else:
            n_socs = np.asarray(normals_bridge, dtype=np.float64) @ rot
            cos_inc = np.abs(np.einsum("ij,ij->i", n_socs, socs)) / r
        new_r = new_r - range_walk.bias_m(r, cos_inc, return_strength(r, cos_inc))
    new_r = new_r * (1.0 + range_scale_ppm * 1e-6)
    return socs * (new_r / r)[:, None]


def random_station(geometry: BridgeGeometry, rng: np.random.Generator, *, height_m: float = 1.5) -> np.ndarray:
    """A scanner position beside the bridge: 20-80 % along the span, 8-20 m to one side."""
    side = rng.choice([-1.0, 1.0])
    return np.array([rng.uniform(0.2, 0.8) * geometry.span_m, side * rng.uniform(8.0, 20.0), height_m])

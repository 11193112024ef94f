"""What the displacement computation takes and gives: observed centroids, reference checks, displacements.

Kept apart from :mod:`lidar.displacement` so that the modules it calls (:mod:`lidar.pier_moves`) can name
its result without importing it.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from common.errors import InputError


@dataclass(frozen=True)
class Observation:
    """A measured target position (scanner frame, metres) and its covariance (m^2)."""

    xyz: np.ndarray
    cov: np.ndarray


class Sighted(Protocol):
    """What the field corrections read of a centroid (e.g. :class:`lidar.centroid.TargetCentroid`).

    Its position in its visit's scanner frame (3,) in metres and its covariance (3, 3) in m^2; the corrections
    also read ``cos_incidence`` and ``time_s`` when a centroid has them.
    """

    @property
    def xyz_socs(self) -> np.ndarray: ...

    @property
    def cov(self) -> np.ndarray: ...


@dataclass(frozen=True)
class ReferenceCheck:
    """Stability of one reference target between the baseline and an epoch."""

    reflector: str
    median_change_m: float
    max_change_m: float
    moved: bool
    missing: bool
    suspect: bool = False  # one of two targets that may have moved; left out of the reference point


#: The terms of a displacement's sigma, in the order the report and the CSV give them.
BUDGET_TERMS = ("noise", "frame", "scale", "bias", "drift")


@dataclass(frozen=True)
class Displacement:
    """Vertical displacement of one measurement target against the baseline (positive up).

    ``along_m`` is its movement along the bridge axis (positive away from the first pier), with
    ``along_sigma_m``. ``budget`` holds the terms of ``sigma_m`` (metres, :data:`BUDGET_TERMS`):
    ``noise`` the target's own centroids, ``frame`` the reference motion and the deck normal, and,
    when a field model corrected the centroids, ``scale``, ``bias`` (range walk) and ``drift``;
    ``sigma_m`` is their sum in quadrature.
    """

    reflector: str
    displacement_m: float
    sigma_m: float
    vertical_m: float
    baseline_vertical_m: float
    flags: tuple[str, ...] = ()
    along_m: float = float("nan")
    along_sigma_m: float = float("nan")
    budget: Mapping[str, float] = field(default_factory=dict)

    @property
    def displacement_mm(self) -> float:
        return self.displacement_m * 1000.0

    @property
    def sigma_mm(self) -> float:
        return self.sigma_m * 1000.0


@dataclass(frozen=True, eq=False)
class Sensitivity:
    """How an epoch's displacements and along-span movements move with its input coordinates.

    ``vertical`` and ``along`` are (n_targets, 3 n_inputs) Jacobians (m per m) of the targets ``targets``;
    ``inputs`` names each input centroid as ``("baseline" | "epoch", id)``, its three columns in order.
    """

    targets: tuple[str, ...]
    inputs: tuple[tuple[str, str], ...]
    vertical: np.ndarray
    along: np.ndarray


@dataclass(frozen=True, eq=False)
class EpochDisplacements:
    """All displacements of one epoch and how they were obtained."""

    displacements: tuple[Displacement, ...]
    reference_ids: tuple[str, ...]
    reference_checks: tuple[ReferenceCheck, ...]
    normal_socs: np.ndarray
    reference_point_socs: np.ndarray
    normal_mode: str
    flags: tuple[str, ...] = ()
    sensitivity: Sensitivity | None = None

    def of(self, reflector: str) -> Displacement:
        for d in self.displacements:
            if d.reflector == reflector:
                return d
        raise InputError(f"no displacement for reflector {reflector!r}")

"""A visit's centroids corrected for the range walk, the set-up's drift and the atmosphere's scale.

For a centroid ``y`` (scanner frame) scanned at time ``t``, with the range walk ``b(r, c)`` along its line of
sight ``u``, the visit's drift rates ``omega`` and scale ``kappa`` (:class:`~lidar.systematic.adjustment.FieldModel`)::

    z = R(omega (t - t_ref)) (y + b u) / (1 + kappa)

``z`` is where the target would have been read by the visit's instrument at ``t_ref``, in the baseline's
atmosphere, without a range walk. :func:`correction_jacobians` gives ``dz`` per unit of each correction's
parameters, so that their uncertainties can be carried through the displacement computation.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from lidar.systematic.adjustment import ARCSEC, VisitSystematics, _drift_rotation, _skew
from lidar.systematic.range_walk import RangeWalkModel, design


@dataclass(frozen=True, eq=False)
class CorrectionJacobian:
    """How one corrected centroid moves with the corrections' parameters (metres per unit).

    ``d_theta`` (3, P) per metre of each range-walk coefficient, ``d_scale`` (3,) per ppm of the
    visit's scale, ``d_drift`` (3, 3) per arcsec/h of each drift rate.
    """

    d_theta: np.ndarray
    d_scale: np.ndarray
    d_drift: np.ndarray


def correct_centroid(xyz_socs: np.ndarray, cos_incidence: float, time_s: float, *, range_walk: RangeWalkModel,
                     visit: VisitSystematics) -> tuple[np.ndarray, CorrectionJacobian]:
    """The corrected centroid (3,) and its :class:`CorrectionJacobian`.

    A time of NaN (or a visit without times) leaves the drift out.
    """
    y = np.asarray(xyz_socs, dtype=np.float64)
    r = float(np.linalg.norm(y))
    u = y / r
    phi = design(range_walk.basis, r, cos_incidence)[0]
    w = y + float(phi @ range_walk.coefficients_m) * u
    dt = (time_s - visit.time_ref_s) if visit.timed and np.isfinite(time_s) else 0.0
    rot = _drift_rotation(visit.drift_arcsec_h, dt)
    sc = 1.0 + 1e-6 * visit.scale_ppm
    z = rot @ w / sc
    jac = CorrectionJacobian(rot @ np.outer(u, phi) / sc, -z * 1e-6 / sc, -_skew(z) * (ARCSEC * dt / 3600.0))
    return z, jac


def correct_visit(centroids: Mapping[str, object], *, range_walk: RangeWalkModel, visit: VisitSystematics
                  ) -> tuple[dict[str, np.ndarray], dict[str, CorrectionJacobian]]:
    """Corrected positions and Jacobians of a visit's centroids (``xyz_socs``, ``cos_incidence``, ``time_s``)."""
    out, jacs = {}, {}
    for k, c in centroids.items():
        z, j = correct_centroid(np.asarray(getattr(c, "xyz_socs")), float(getattr(c, "cos_incidence", 1.0)),
                                float(getattr(c, "time_s", float("nan"))), range_walk=range_walk, visit=visit)
        out[k], jacs[k] = z, j
    return out, jacs

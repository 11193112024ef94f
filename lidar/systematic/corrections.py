"""A visit's centroids corrected for the range walk, the set-up's drift and the atmosphere's scale.

For a centroid ``y`` (scanner frame) scanned at time ``t``, with the range walk ``b(r, c)`` along its line of
sight ``u``, the visit's drift rates ``omega`` and scale ``kappa`` (:class:`~lidar.systematic.adjustment.FieldModel`)::

    z = R(omega (t - t_ref)) (y + b u) / (1 + kappa)

``z`` is where the target would have been read by the visit's instrument at ``t_ref``, in the baseline's
atmosphere, without a range walk (and without the instrument's axis errors, when the campaign fitted them:
``y`` then gains their correction before the drift's rotation, :mod:`lidar.systematic.axes`). :func:`correction_jacobians` gives ``dz`` per unit of each correction's
parameters, so that their uncertainties can be carried through the displacement computation.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from common.rigid import skew
from lidar.displacement_result import Sighted
from lidar.systematic.adjustment import ARCSEC, VisitSystematics, drift_rotation
from lidar.systematic.axes import AxisModel, axis_basis
from lidar.systematic.range_walk import RangeWalkModel, design


@dataclass(frozen=True, eq=False)
class CorrectionJacobian:
    """How one corrected centroid moves with the corrections' parameters (metres per unit).

    ``d_theta`` (3, P) per metre of each range-walk coefficient, ``d_scale`` (3,) per ppm of the
    visit's scale, ``d_drift`` (3, 3) per arcsec/h of each drift rate, ``d_axes`` (3, A) per arcsec of each of
    the instrument's axis errors (A = 0 when none were fitted).
    """

    d_theta: np.ndarray
    d_scale: np.ndarray
    d_drift: np.ndarray
    d_axes: np.ndarray = field(default_factory=lambda: np.zeros((3, 0)))


def correct_centroid(xyz_socs: np.ndarray, cos_incidence: float, time_s: float, *, range_walk: RangeWalkModel,
                     visit: VisitSystematics, axes: AxisModel = AxisModel()) -> tuple[np.ndarray, CorrectionJacobian]:
    """The corrected centroid (3,) and its :class:`CorrectionJacobian`.

    A time of NaN (or a visit without times) leaves the drift out; ``axes`` are the instrument's axis errors
    (:mod:`lidar.systematic.axes`; none by default).
    """
    y = np.asarray(xyz_socs, dtype=np.float64)
    r = float(np.linalg.norm(y))
    u = y / r
    phi = design(range_walk.basis, r, cos_incidence)[0]
    along_axes = axis_basis(y[None])[0][:, list(axes.terms)]
    w = y + float(phi @ range_walk.coefficients_m) * u + along_axes @ axes.values_arcsec
    dt = (time_s - visit.time_ref_s) if visit.timed and np.isfinite(time_s) else 0.0
    rot = drift_rotation(visit.drift_arcsec_h, dt)
    sc = 1.0 + 1e-6 * visit.scale_ppm
    z = rot @ w / sc
    jac = CorrectionJacobian(rot @ np.outer(u, phi) / sc, -z * 1e-6 / sc, -skew(z) * (ARCSEC * dt / 3600.0),
                             rot @ along_axes / sc)
    return z, jac


def cos_incidence_of(centroid: object) -> float:
    """A centroid's |cos| of incidence, 1 (head-on) when it is not known (a centroid stored without its normal)."""
    c = float(getattr(centroid, "cos_incidence", float("nan")))
    return c if np.isfinite(c) else 1.0


def correct_visit(centroids: Mapping[str, Sighted], *, range_walk: RangeWalkModel, visit: VisitSystematics,
                  axes: AxisModel = AxisModel()) -> tuple[dict[str, np.ndarray], dict[str, CorrectionJacobian]]:
    """Corrected positions and Jacobians of a visit's centroids (``xyz_socs``, ``cos_incidence``, ``time_s``).

    The targets of a pier the model found moved along the span in this visit (``visit.shifted``) are moved back
    by its shift, so that they stand where the baseline saw them (:mod:`lidar.systematic.pier_slide`).
    """
    out, jacs = {}, {}
    for k, c in centroids.items():
        z, j = correct_centroid(np.asarray(c.xyz_socs), cos_incidence_of(c),
                                float(getattr(c, "time_s", float("nan"))), range_walk=range_walk, visit=visit,
                                axes=axes)
        if k in visit.shifted:
            z = z - visit.shift_m * np.asarray(visit.shift_socs)
        out[k], jacs[k] = z, j
    return out, jacs


@dataclass(frozen=True)
class ClosureDrift:
    """How far the set-up turned between a target's first window and its closure window.

    ``angle_arcsec`` is the turn seen across the line of sight (a rotation about the line of sight itself
    does not move a point), with its ``sigma_arcsec`` from both centroids' covariances, over ``dt_s``
    seconds; ``rate_arcsec_h`` the same per hour.
    """

    reflector: str
    angle_arcsec: float
    sigma_arcsec: float
    dt_s: float

    @property
    def rate_arcsec_h(self) -> float:
        return self.angle_arcsec / self.dt_s * 3600.0 if self.dt_s > 0 else float("nan")


def closure_drift(first: Sighted, closure: Sighted) -> ClosureDrift:
    """The set-up's turn between a target's first centroid and its closure centroid (same target, same visit)."""
    a = np.asarray(first.xyz_socs, dtype=np.float64)
    b = np.asarray(closure.xyz_socs, dtype=np.float64)
    r = float(np.linalg.norm(a))
    u = a / r
    perp = np.eye(3) - np.outer(u, u)
    d = perp @ (b - a)
    cov = perp @ (np.asarray(first.cov) + np.asarray(closure.cov)) @ perp
    dist = float(np.linalg.norm(d))
    var = float(d @ cov @ d) / dist ** 2 if dist > 0 else float(np.trace(cov)) / 2.0
    to_arcsec = 1.0 / r / ARCSEC
    dt = float(getattr(closure, "time_s", np.nan)) - float(getattr(first, "time_s", np.nan))
    return ClosureDrift(str(getattr(first, "reflector", "")), dist * to_arcsec, float(np.sqrt(var)) * to_arcsec,
                        dt if np.isfinite(dt) else float("nan"))

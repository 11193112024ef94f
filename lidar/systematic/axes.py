"""The instrument's own axis errors: a vertical index, a collimation and a trunnion-axis error, one set a campaign.

A scanner whose calibration leaves them reports a beam at zenith angle ``theta`` and azimuth ``phi`` that left
at zenith ``theta + e`` (the vertical index ``e``) and at azimuth ``phi + c / sin(theta) + i cot(theta)`` (the
collimation ``c`` and the trunnion axis' tilt ``i``), the classic errors of a theodolite's axes. Specified
angular accuracies of 8-20 arcsec are common; a vertical index of 30 arcsec moves a target 20 m away by 3 mm
across its line of sight, and differently from every station, so the displacements (vectors between
targets of one visit) do not cancel it: with 20/20/15 arcsec and a 3 mm zero error, 2.9 % of the displacements
and 46 % of the along-span movements were beyond 3 sigma with no flag before they were fitted
(``./run bench field_effects``).

The same instrument's errors are the same at every visit, so the campaign's adjustment
(:mod:`lidar.systematic.adjustment`) fits them as three unknowns shared by all visits, from the reference
targets seen from different stations and the deck targets' across-span coordinates, and a centroid ``y``
(range ``r``) is corrected by::

    y + r (e e_theta + (c + i cos(theta)) e_phi)      (angles in radians)

with ``e_theta`` and ``e_phi`` the unit vectors of growing zenith and azimuth at ``y``: to first order the
point the beam really met (the second order is below a micrometre at 60 arcsec and 30 m).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

#: One arcsecond in radians.
ARCSEC = math.pi / 180.0 / 3600.0
#: Prior standard deviation of each axis error (arcsec): an instrument within its specification or a little out.
PRIOR_AXES_ARCSEC = 60.0
#: Names of the three errors, in the order of :attr:`AxisModel.values_arcsec`.
AXIS_NAMES = ("vertical index", "collimation", "trunnion axis")
#: Format version of an axis model's JSON form.
AXES_FORMAT_VERSION = 1


def axis_basis(xyz_socs: np.ndarray) -> np.ndarray:
    """(N, 3, 3) how each reported point moves per arcsec of (vertical index, collimation, trunnion) error.

    Parameters
    ----------
    xyz_socs : (N, 3) float64 array
        Points as the instrument reported them, scanner frame, metres.

    Returns
    -------
    (N, 3, 3) float64 array, metres per arcsec: column ``k`` is the correction per arcsec of error ``k``.
    """
    y = np.asarray(xyz_socs, dtype=np.float64).reshape(-1, 3)
    r = np.linalg.norm(y, axis=1)
    horizontal = np.hypot(y[:, 0], y[:, 1])
    safe = np.maximum(horizontal, 1e-12)
    cos_phi, sin_phi = y[:, 0] / safe, y[:, 1] / safe
    cos_t, sin_t = y[:, 2] / np.maximum(r, 1e-12), horizontal / np.maximum(r, 1e-12)
    e_theta = np.stack([cos_t * cos_phi, cos_t * sin_phi, -sin_t], axis=1)
    e_phi = np.stack([-sin_phi, cos_phi, np.zeros_like(r)], axis=1)
    scale = (r * ARCSEC)[:, None]
    return np.stack([e_theta * scale, e_phi * scale, e_phi * (scale * cos_t[:, None])], axis=2)


def errors_text(errors: Iterable[tuple[str, float, float]]) -> str:
    """``vertical index +28.7 ± 7.8″; trunnion axis -3.0 ± 1.1″`` of (name, arcsec, sigma); empty without any."""
    return "; ".join(f"{name} {value:+.1f} ± {sigma:.1f}″" for name, value, sigma in errors)


@dataclass(frozen=True, eq=False)
class AxisModel:
    """A campaign's fitted axis errors (arcsec) and their covariance (arcsec^2).

    Attributes
    ----------
    terms : tuple of int
        Which errors were fitted (indices into :data:`AXIS_NAMES`): those the campaign's data support (BIC);
        empty when none.
    values_arcsec : (T,) float64 array
    covariance_arcsec2 : (T, T) float64 array
    """

    terms: tuple[int, ...] = ()
    values_arcsec: np.ndarray = field(default_factory=lambda: np.zeros(0))
    covariance_arcsec2: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def fitted(self) -> bool:
        return bool(self.terms)

    def errors(self) -> list[tuple[str, float, float]]:
        """(name, arcsec, sigma in arcsec) of every fitted error."""
        sig = np.sqrt(np.maximum(np.diag(self.covariance_arcsec2), 0.0))
        return [(AXIS_NAMES[k], float(v), float(s))
                for k, v, s in zip(self.terms, self.values_arcsec, sig, strict=False)]

    def describe(self) -> str:
        """``vertical index +28.7 ± 7.8″``, one clause per fitted error (:func:`errors_text`); ``none`` without."""
        return errors_text(self.errors()) or "none"

    def to_json(self) -> dict:
        return {"format_version": AXES_FORMAT_VERSION, "terms": [AXIS_NAMES[k] for k in self.terms],
                "values_arcsec": self.values_arcsec.tolist(), "covariance_arcsec2": self.covariance_arcsec2.tolist()}

    @classmethod
    def from_json(cls, d: dict | None) -> AxisModel:
        if not d or not d.get("terms"):
            return cls()
        terms = tuple(AXIS_NAMES.index(t) for t in d["terms"])
        n = len(terms)
        return cls(terms, np.asarray(d["values_arcsec"], dtype=np.float64).reshape(n),
                   np.asarray(d["covariance_arcsec2"], dtype=np.float64).reshape(n, n))

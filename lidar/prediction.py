"""What a fine scan of a target will deliver, before it is taken: points and centroid covariance.

The model is the one the centroid estimator reports (:func:`lidar.centroid.target_centroid`):
range noise along the viewing direction divided by the number of disc points, plus the rim
term in the disc plane (about ``2 pi R / spacing`` rim points each in or out, moving the
centroid by ``R / n``). That rim term is what a thresholded disc gives and what a target that
saturates the receiver keeps; where the rim's mixed returns are graded, the centroid weighs them
(:func:`lidar.centroid.weighted_centre`) and does 2-4 times better across the line of sight, which
the scan shows and the plan cannot know. The prediction is therefore an upper bound in the disc's
plane. Used by the station advisor and the on-site check.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from lidar.centroid import grazing_covariance, resolvability, rim_variance
from lidar.scanner_profile import ScannerProfile


def disc_points(diameter_m: float, range_m: float, cos_incidence: float, theta_deg: float,
                theta_step_deg: float, phi_step_deg: float) -> float:
    """Expected points on a disc target: its solid angle over one scan cell's.

    Parameters
    ----------
    diameter_m, range_m : float
        Target diameter and range, metres.
    cos_incidence : float
        |cos| of the angle between the target's normal and the line of sight.
    theta_deg : float
        Zenith angle of the target in the scanner frame (a cell shrinks with sin(theta)).
    theta_step_deg, phi_step_deg : float
        Angular steps of the scan, degrees.
    """
    omega = math.pi * (diameter_m / 2) ** 2 * max(cos_incidence, 0.0) / range_m ** 2
    cell = math.radians(theta_step_deg) * math.radians(phi_step_deg) * max(math.sin(math.radians(theta_deg)), 1e-3)
    return omega / cell


def centroid_covariance(xyz_socs: ArrayLike, normal_socs: ArrayLike, n_points: float, *, diameter_m: float = 0.05,
                        range_noise_m: float = 0.005, profile: ScannerProfile | None = None) -> np.ndarray:
    """(3, 3) covariance of a target centroid from ``n_points`` disc points, m^2.

    Parameters
    ----------
    xyz_socs : (3,) array
        Target centre in the scanner frame, metres.
    normal_socs : (3,) array
        Target normal in the scanner frame.
    n_points : float
        Points on the disc.
    diameter_m : float, keyword-only
    range_noise_m : float, keyword-only
        One-point range standard deviation, metres.
    profile : ScannerProfile, optional, keyword-only
        The instrument: with it, a disc narrower than the beam at this range and incidence gets the
        grazing term processing adds (:func:`lidar.centroid.grazing_covariance`). Default: none added.
    """
    x = np.asarray(xyz_socs, dtype=np.float64)
    nrm = np.asarray(normal_socs, dtype=np.float64)
    if x.shape != (3,) or nrm.shape != (3,) or not (np.all(np.isfinite(x)) and np.all(np.isfinite(nrm))):
        raise InputError("centroid_covariance needs a finite (3,) position and normal")
    n = max(float(n_points), 1.0)
    radius = diameter_m / 2
    view = x / np.linalg.norm(x)
    nrm = nrm / np.linalg.norm(nrm)
    cov = range_noise_m ** 2 / n * np.outer(view, view)
    spacing = math.sqrt(math.pi * radius ** 2 / n)
    cov += rim_variance(radius, n, spacing) * (np.eye(3) - np.outer(nrm, nrm))
    if profile is not None:
        cos = abs(float(nrm @ view))
        q = resolvability(diameter_m, cos, float(np.linalg.norm(x)), profile)
        cov += grazing_covariance(view, nrm, diameter_m=diameter_m, cos_incidence=cos,
                                  footprint_m=float(profile.footprint_m(float(np.linalg.norm(x)))), ratio=q)
    return cov

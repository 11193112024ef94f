"""Scanner profiles: what an instrument can do and how it spends time."""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Optional

from lidar.errors import InputError
from lidar.identification import MAX_TILT_DEG


@dataclass(frozen=True)
class ScannerProfile:
    """Capabilities of a terrestrial laser scanner.

    The defaults are the Riegl VZ-1000 of the dissertation's LiDAR
    specification table: up to 122,000 points/s, 5 mm range standard
    deviation, finest steps 0.001 deg vertical and 0.006 deg horizontal.

    A line scanner sweeps its whole vertical field of view with a rotating
    mirror while the head turns slowly in azimuth; it fires at the pulse rate
    over the whole sweep and keeps only returns inside the window. A window's
    time is therefore set by its number of vertical lines, each costing
    ``vertical_fov / theta_step / pulse_rate`` seconds (bounded by the mirror's
    line-rate limits), not by the points it keeps.

    Attributes
    ----------
    name : str
    pulse_rate_hz : float
        Measurement rate, points per second.
    range_noise_m : float
        Range standard deviation, metres.
    min_theta_step_deg, min_phi_step_deg : float
        Finest vertical (zenith) and horizontal (azimuth) steps, degrees.
    theta_fov_deg : (float, float)
        Zenith angles the mirror sweeps, degrees (VZ-1000: +60/-40 deg elevation).
    max_line_rate_hz : float
        Fastest mirror line rate, lines per second.
    window_overhead_s : float
        Time to turn the head to a window and start it, seconds.
    beam_divergence_mrad, beam_exit_diameter_m : float
        Footprint model: diameter = exit + divergence * range.
    max_range_m : float
    max_tilt_deg : float or None
        Largest scanner tilt an identification of the coarse scan may imply.
        The VZ-1000's inclination sensors hold a levelled set-up to about
        0.01 deg; the default 2 deg leaves room for a layout's few centimetres of
        error over a few metres. None for an instrument without compensator.
    """

    name: str = "Riegl VZ-1000"
    pulse_rate_hz: float = 122_000.0
    range_noise_m: float = 0.005
    min_theta_step_deg: float = 0.001
    min_phi_step_deg: float = 0.006
    theta_fov_deg: tuple[float, float] = (30.0, 130.0)
    max_line_rate_hz: float = 120.0
    window_overhead_s: float = 3.0
    beam_divergence_mrad: float = 0.3
    beam_exit_diameter_m: float = 0.007
    max_range_m: float = 1400.0
    max_tilt_deg: Optional[float] = MAX_TILT_DEG

    def __post_init__(self) -> None:
        for k, v in asdict(self).items():
            if k in ("name", "theta_fov_deg") or (k == "max_tilt_deg" and v is None):
                continue
            if not (isinstance(v, (int, float)) and v > 0):
                raise InputError(f"scanner profile: {k} must be a positive number, got {v!r}")
        lo, hi = self.theta_fov_deg
        if not 0 <= lo < hi <= 180:
            raise InputError(f"scanner profile: theta_fov_deg must satisfy 0 <= lo < hi <= 180, got {self.theta_fov_deg}")

    @property
    def vertical_fov_deg(self) -> float:
        return self.theta_fov_deg[1] - self.theta_fov_deg[0]

    def footprint_m(self, range_m):
        """Beam footprint diameter at a range, metres."""
        return self.beam_exit_diameter_m + self.beam_divergence_mrad * 1e-3 * range_m

    def line_seconds(self, theta_step_deg: float) -> float:
        """Seconds one vertical mirror line takes at a vertical step."""
        t = self.vertical_fov_deg / theta_step_deg / self.pulse_rate_hz
        return max(t, 1.0 / self.max_line_rate_hz)

    def window_seconds(self, phi_width_deg: float, phi_step_deg: float, theta_step_deg: float) -> float:
        """Seconds to scan an azimuth range at the given steps, including the overhead."""
        lines = int(phi_width_deg / phi_step_deg) + 1
        return self.window_overhead_s + lines * self.line_seconds(theta_step_deg)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["theta_fov_deg"] = list(self.theta_fov_deg)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "ScannerProfile":
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        if "theta_fov_deg" in known:
            known["theta_fov_deg"] = tuple(known["theta_fov_deg"])
        return cls(**known)


VZ1000 = ScannerProfile()

"""Scanner profiles: what an instrument can do and how it spends time.

The catalogue of named instruments is in :mod:`lidar.scanner_catalogue`; a profile can also be
read from a JSON file (:func:`load_profile`).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError

#: Default largest scanner tilt a solution may imply and still count as levelled (degrees). Compensators
#: hold a levelled scanner to hundredths of a degree; the rest is the layout's few centimetres of error.
MAX_TILT_DEG = 2.0


@dataclass(frozen=True)
class ScannerProfile:
    """Capabilities of a terrestrial laser scanner.

    The defaults are the Riegl VZ-1000 of the dissertation's LiDAR
    specification table: up to 122,000 points/s, 5 mm range standard
    deviation, finest steps 0.001 deg vertical and 0.006 deg horizontal.

    Every instrument of the catalogue sweeps a vertical line with a rotating
    mirror while the head turns slowly in azimuth; it measures at its rate over
    the whole sweep and keeps only returns inside the window. A window's time
    is therefore set by its number of vertical lines, each costing
    ``line_sweep_deg / theta_step / pulse_rate`` seconds (bounded by the
    mirror's line-rate limit), not by the points it keeps. A Riegl VZ's polygon
    sweeps its 100 deg field of view (``kind="line"``); a phase-based or
    panoramic scanner's mirror turns a full 360 deg per line (``kind="panoramic"``).

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
    kind : {"line", "panoramic"}
        How the mirror sweeps (see above).
    step_presets : tuple of (label, step_deg)
        The resolutions the instrument offers, when it offers only presets
        (phase-based scanners: "6.3 mm @ 10 m", "1/4"...): the same angular
        step horizontally and vertically. Empty: any step down to the finest.
    windowed : bool
        Whether a scan can be limited to an angular window. False: the plan is
        one full-dome scan at one preset, from which every target's window is cut.
    horizontal_direction : {"ccw", "cw"}
        Sense in which the instrument's horizontal angle grows, seen from above
        (our scanner frame's azimuth grows counter-clockwise from +x).
    horizontal_zero_deg : float
        The instrument's horizontal zero, as an azimuth of our scanner frame.
    vertical_reference : {"zenith", "elevation"}
        Whether the instrument shows vertical angles from the zenith or as elevation.
    resolution_label : str
        How the instrument's panel names a resolution ("step", "mm at 10 m", "pts/360 deg"...).
    quality : str
        The quality (noise-averaging) setting the rate assumes, for instruments that have one
        ("4x" on a FARO); entered with every window.
    wavelength_nm : float
        The ranging laser's wavelength, for the air's refractive index (:mod:`lidar.systematic.atmosphere`).
    drift_tolerance_arcsec : float
        How far the set-up may turn during one visit before its drift is worth a warning (tilt or twist,
        arcseconds from the first window to the last).
    sources : tuple of (field, source)
        Where each value comes from.
    notes : str
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
    max_tilt_deg: float | None = MAX_TILT_DEG
    kind: str = "line"
    step_presets: tuple[tuple[str, float], ...] = ()
    windowed: bool = True
    horizontal_direction: str = "ccw"
    horizontal_zero_deg: float = 0.0
    vertical_reference: str = "zenith"
    resolution_label: str = "step"
    quality: str = ""
    wavelength_nm: float = 1550.0
    drift_tolerance_arcsec: float = 10.0
    sources: tuple[tuple[str, str], ...] = ()
    notes: str = ""

    def __post_init__(self) -> None:
        for k in ("pulse_rate_hz", "range_noise_m", "min_theta_step_deg", "min_phi_step_deg", "max_line_rate_hz",
                  "window_overhead_s", "beam_divergence_mrad", "beam_exit_diameter_m", "max_range_m",
                  "wavelength_nm", "drift_tolerance_arcsec"):
            v = getattr(self, k)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"scanner profile {self.name!r}: {k} must be a positive number, got {v!r}")
        if self.max_tilt_deg is not None and not (isinstance(self.max_tilt_deg, (int, float)) and self.max_tilt_deg > 0):
            raise InputError(f"scanner profile {self.name!r}: max_tilt_deg must be positive or null")
        lo, hi = self.theta_fov_deg
        if not 0 <= lo < hi <= 180:
            raise InputError(f"scanner profile {self.name!r}: theta_fov_deg must satisfy 0 <= lo < hi <= 180, "
                             f"got {self.theta_fov_deg}")
        choices = {"kind": ("line", "panoramic"), "horizontal_direction": ("ccw", "cw"),
                   "vertical_reference": ("zenith", "elevation")}
        for k, allowed in choices.items():
            if getattr(self, k) not in allowed:
                raise InputError(f"scanner profile {self.name!r}: {k} must be one of {', '.join(allowed)}, "
                                 f"got {getattr(self, k)!r}")
        presets = tuple((str(lab), float(st)) for lab, st in self.step_presets)
        if any(not (math.isfinite(st) and st > 0) for _, st in presets):
            raise InputError(f"scanner profile {self.name!r}: every step preset needs a positive step in degrees")
        object.__setattr__(self, "step_presets", tuple(sorted(presets, key=lambda p: p[1])))
        object.__setattr__(self, "sources", tuple((str(a), str(b)) for a, b in self.sources))
        object.__setattr__(self, "theta_fov_deg", (float(lo), float(hi)))
        if not self.windowed and not self.step_presets:
            raise InputError(f"scanner profile {self.name!r}: a full-dome-only scanner needs step_presets")

    @property
    def vertical_fov_deg(self) -> float:
        return self.theta_fov_deg[1] - self.theta_fov_deg[0]

    @property
    def line_sweep_deg(self) -> float:
        """Degrees of mirror sweep per vertical line during which the instrument measures."""
        return 360.0 if self.kind == "panoramic" else self.vertical_fov_deg

    def preset_for(self, step_deg: float) -> tuple[str, float]:
        """The coarsest preset no coarser than ``step_deg`` (the finest when none is fine enough)."""
        if not self.step_presets:
            return (f"{step_deg:.4f} deg", step_deg)
        fine_enough = [p for p in self.step_presets if p[1] <= step_deg * (1 + 1e-9)]
        return fine_enough[-1] if fine_enough else self.step_presets[0]

    def preset_label(self, step_deg: float) -> str:
        """The instrument's own name for a step (the preset's label, or the step in degrees)."""
        for lab, st in self.step_presets:
            if abs(st - step_deg) <= 1e-9 + 1e-6 * st:
                return lab
        return f"{step_deg:.4f} deg"

    def full_dome_seconds(self, step_deg: float) -> float:
        """Seconds of one full-dome scan at a step (overhead included)."""
        return self.window_seconds(360.0, step_deg, step_deg)

    def instrument_angles(self, theta_deg: ArrayLike, phi_deg: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Our (zenith theta, azimuth phi) as the instrument shows them: (horizontal, vertical), degrees."""
        phi = np.asarray(phi_deg, dtype=np.float64)
        theta = np.asarray(theta_deg, dtype=np.float64)
        rel = phi - self.horizontal_zero_deg
        hz = np.mod(rel if self.horizontal_direction == "ccw" else -rel, 360.0)
        v = theta if self.vertical_reference == "zenith" else 90.0 - theta
        return hz, v

    def angle_convention(self) -> str:
        """One line saying how the instrument counts its angles."""
        sense = "counter-clockwise" if self.horizontal_direction == "ccw" else "clockwise"
        vert = "zenith angle (0 = straight up)" if self.vertical_reference == "zenith" else \
            "elevation (0 = horizontal, + up)"
        return f"horizontal angle grows {sense} seen from above from the instrument's zero; vertical: {vert}"

    def footprint_m(self, range_m: ArrayLike) -> float | np.ndarray:
        """Beam footprint diameter at a range, metres."""
        fp = self.beam_exit_diameter_m + self.beam_divergence_mrad * 1e-3 * np.asarray(range_m, dtype=np.float64)
        return float(fp) if fp.ndim == 0 else fp

    def line_seconds(self, theta_step_deg: float) -> float:
        """Seconds one vertical mirror line takes at a vertical step."""
        t = self.line_sweep_deg / theta_step_deg / self.pulse_rate_hz
        return max(t, 1.0 / self.max_line_rate_hz)

    def window_seconds(self, phi_width_deg: float, phi_step_deg: float, theta_step_deg: float) -> float:
        """Seconds to scan an azimuth range at the given steps, including the overhead."""
        lines = int(phi_width_deg / phi_step_deg) + 1
        return self.window_overhead_s + lines * self.line_seconds(theta_step_deg)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["theta_fov_deg"] = list(self.theta_fov_deg)
        d["step_presets"] = [{"label": lab, "step_deg": st} for lab, st in self.step_presets]
        d["sources"] = dict(self.sources)
        return d

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "scanner profile") -> ScannerProfile:
        if not isinstance(d, dict):
            raise InputError(f"{source}: a scanner profile is a JSON object")
        known = {k: v for k, v in d.items() if k in cls.__dataclass_fields__}
        try:
            if "theta_fov_deg" in known:
                known["theta_fov_deg"] = tuple(float(v) for v in known["theta_fov_deg"])
            if "step_presets" in known:
                known["step_presets"] = tuple((p["label"], float(p["step_deg"])) if isinstance(p, dict)
                                              else (p[0], float(p[1])) for p in known["step_presets"])
            if isinstance(known.get("sources"), dict):
                known["sources"] = tuple(known["sources"].items())
            return cls(**known)
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None
        except (TypeError, ValueError, KeyError, IndexError) as exc:
            raise InputError(f"{source}: malformed scanner profile ({exc!r})") from None


def load_profile(path: str | os.PathLike) -> ScannerProfile:
    """A user-defined profile from a JSON file (the fields of :class:`ScannerProfile`; ``name`` required)."""
    p = Path(path)
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{p}: scanner profile file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{p}: not a JSON scanner profile ({exc})") from None
    if not isinstance(d, dict) or not str(d.get("name", "")).strip():
        raise InputError(f"{p}: a scanner profile needs a 'name'")
    return ScannerProfile.from_dict(d, source=str(p))


VZ1000 = ScannerProfile()

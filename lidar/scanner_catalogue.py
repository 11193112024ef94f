"""Terrestrial laser scanners used for structural monitoring, as planning profiles.

Each value carries its source. The manufacturers' public specification sheets are cited by title;
this build had no copy of them to check against, so every figure was transcribed from those sheets
as published and should be compared with the sheet of the user's own instrument (firmware changes
presets and rates). A profile file (``init --scanner FILE``) overrides any of them.

Values that no sheet gives are marked ``assumed`` with the reasoning, for example the per-window
overhead (turning the head, starting the scan, the operator entering the window), which the
dissertation's field figures calibrate for the VZ-1000 (3 min for 1000 points on a pier target).

Angle conventions: Riegl's RiSCAN shows the scanner's own spherical frame (azimuth counter-clockwise
from the instrument's x axis, polar angle from the zenith), the frame our scans are in. Leica and
Trimble panels follow the theodolite convention (horizontal angle clockwise, vertical angle from the
zenith); FARO and Z+F panels define a scan area by horizontal limits and vertical limits as
elevation (FARO) or zenith angle (Z+F). Where an instrument's zero is not the x axis of the
exported scan, the field sheet's check line (aim at the first target and compare) catches it.
"""
from __future__ import annotations

import math

from common.errors import InputError
from lidar.scanner_profile import ScannerProfile, load_profile


def _mm_at_10m(*spacings_mm: float) -> tuple[tuple[str, float], ...]:
    """Presets given as point spacing at 10 m, as angular steps."""
    return tuple((f"{s:g} mm @ 10 m", math.degrees(math.atan(s / 1000.0 / 10.0))) for s in spacings_mm)


def _per_360(named: dict[str, int]) -> tuple[tuple[str, float], ...]:
    """Presets given as points per full 360 deg turn."""
    return tuple((f"{name} ({n:,} pts/360°)", 360.0 / n) for name, n in named.items())


def _sheet(title: str) -> str:
    return f"{title} (manufacturer's public specification sheet)"


# Per-window overhead: head turn, scan start and the operator entering the window. Calibrated on the
# dissertation's VZ-1000 figure (3 min for 1000 points on a pier target; bench/plan_predictions.py
# shows the fit); the same operator time is assumed for the other instruments.
OVERHEAD_S = 120.0
_OVERHEAD_SOURCE = ("assumed: 120 s per window (head turn, scan start, operator entering the window), "
                    "calibrated on the dissertation's 3 min for 1000 points at the pier (section 4.3.2)")

_RIEGL_CONVENTION = "RiSCAN PRO SOCS: azimuth counter-clockwise from the scanner's x axis, polar angle from zenith"
_THEODOLITE = "theodolite convention on the panel: Hz clockwise, V from the zenith (check on site)"

CATALOGUE: dict[str, ScannerProfile] = {}


def _add(p: ScannerProfile) -> None:
    CATALOGUE[p.name] = p


_add(ScannerProfile(
    name="Riegl VZ-1000", kind="line", pulse_rate_hz=122_000.0, range_noise_m=0.005,
    min_theta_step_deg=0.001, min_phi_step_deg=0.006, theta_fov_deg=(30.0, 130.0), max_line_rate_hz=120.0,
    window_overhead_s=OVERHEAD_S, beam_divergence_mrad=0.3, beam_exit_diameter_m=0.007, max_range_m=1400.0,
    windowed=True, horizontal_direction="ccw", vertical_reference="zenith", resolution_label="step (deg)",
    sources=(("pulse_rate_hz", "dissertation Table 13: up to 122,000 points/s"),
             ("range_noise_m", "dissertation Table 13: distance standard deviation 5 mm"),
             ("min_theta_step_deg", "dissertation Table 13: vertical 0.001 deg (sheet: 0.0024 deg)"),
             ("min_phi_step_deg", "dissertation Table 13: horizontal 0.006 deg"),
             ("theta_fov_deg", _sheet("RIEGL VZ-1000 data sheet") + ": 100 deg vertical, +60/-40 deg"),
             ("max_line_rate_hz", _sheet("RIEGL VZ-1000 data sheet") + ": 3 to 120 lines/s"),
             ("beam_divergence_mrad", _sheet("RIEGL VZ-1000 data sheet") + ": 0.3 mrad"),
             ("beam_exit_diameter_m", "assumed: 7 mm at the exit aperture"),
             ("max_range_m", _sheet("RIEGL VZ-1000 data sheet") + ": 1400 m at 80 % reflectivity"),
             ("windowed", "RiSCAN PRO: panorama and detail scans with free angular limits"),
             ("angles", _RIEGL_CONVENTION),
             ("window_overhead_s", _OVERHEAD_SOURCE)),
    notes="The dissertation's instrument (chapters 4 and 5)."))

_add(ScannerProfile(
    name="Riegl VZ-400i", kind="line", pulse_rate_hz=500_000.0, range_noise_m=0.003,
    min_theta_step_deg=0.0007, min_phi_step_deg=0.0015, theta_fov_deg=(30.0, 130.0), max_line_rate_hz=240.0,
    window_overhead_s=OVERHEAD_S, beam_divergence_mrad=0.35, beam_exit_diameter_m=0.007, max_range_m=800.0,
    windowed=True, horizontal_direction="ccw", vertical_reference="zenith", resolution_label="step (deg)",
    sources=(("pulse_rate_hz", _sheet("RIEGL VZ-400i data sheet") + ": effective measurement rate up to 500,000 meas./s"),
             ("range_noise_m", _sheet("RIEGL VZ-400i data sheet") + ": precision 3 mm (accuracy 5 mm)"),
             ("min_theta_step_deg", _sheet("RIEGL VZ-400i data sheet") + ": vertical step >= 0.0007 deg"),
             ("min_phi_step_deg", _sheet("RIEGL VZ-400i data sheet") + ": horizontal step >= 0.0015 deg"),
             ("theta_fov_deg", _sheet("RIEGL VZ-400i data sheet") + ": 100 deg vertical, +60/-40 deg"),
             ("max_line_rate_hz", _sheet("RIEGL VZ-400i data sheet") + ": up to 240 lines/s"),
             ("beam_divergence_mrad", _sheet("RIEGL VZ-400i data sheet") + ": 0.35 mrad"),
             ("beam_exit_diameter_m", "assumed: 7 mm, as the VZ-1000"),
             ("max_range_m", _sheet("RIEGL VZ-400i data sheet") + ": 800 m at 90 % reflectivity"),
             ("windowed", "RiSCAN PRO / VZ-i series: detail scans with free angular limits"),
             ("angles", _RIEGL_CONVENTION), ("window_overhead_s", _OVERHEAD_SOURCE))))

_add(ScannerProfile(
    name="Riegl VZ-2000i", kind="line", pulse_rate_hz=500_000.0, range_noise_m=0.003,
    min_theta_step_deg=0.0007, min_phi_step_deg=0.0015, theta_fov_deg=(30.0, 130.0), max_line_rate_hz=240.0,
    window_overhead_s=OVERHEAD_S, beam_divergence_mrad=0.27, beam_exit_diameter_m=0.007, max_range_m=2500.0,
    windowed=True, horizontal_direction="ccw", vertical_reference="zenith", resolution_label="step (deg)",
    sources=(("pulse_rate_hz", _sheet("RIEGL VZ-2000i data sheet") + ": effective measurement rate up to 500,000 meas./s"),
             ("range_noise_m", _sheet("RIEGL VZ-2000i data sheet") + ": precision 3 mm (accuracy 5 mm)"),
             ("min_theta_step_deg", _sheet("RIEGL VZ-2000i data sheet") + ": vertical step >= 0.0007 deg"),
             ("min_phi_step_deg", _sheet("RIEGL VZ-2000i data sheet") + ": horizontal step >= 0.0015 deg"),
             ("theta_fov_deg", _sheet("RIEGL VZ-2000i data sheet") + ": 100 deg vertical, +60/-40 deg"),
             ("max_line_rate_hz", _sheet("RIEGL VZ-2000i data sheet") + ": up to 240 lines/s"),
             ("beam_divergence_mrad", _sheet("RIEGL VZ-2000i data sheet") + ": 0.27 mrad"),
             ("beam_exit_diameter_m", "assumed: 7 mm, as the VZ-1000"),
             ("max_range_m", _sheet("RIEGL VZ-2000i data sheet") + ": 2500 m at 90 % reflectivity"),
             ("windowed", "RiSCAN PRO / VZ-i series: detail scans with free angular limits"),
             ("angles", _RIEGL_CONVENTION), ("window_overhead_s", _OVERHEAD_SOURCE))))

_P50 = _sheet("Leica ScanStation P50 data sheet")
_add(ScannerProfile(
    name="Leica ScanStation P50", kind="panoramic", pulse_rate_hz=1_000_000.0, range_noise_m=0.0005,
    min_theta_step_deg=math.degrees(math.atan(0.0008 / 10)), min_phi_step_deg=math.degrees(math.atan(0.0008 / 10)),
    theta_fov_deg=(0.0, 145.0), max_line_rate_hz=100.0, window_overhead_s=OVERHEAD_S,
    beam_divergence_mrad=0.23, beam_exit_diameter_m=0.0035, max_range_m=1000.0,
    step_presets=_mm_at_10m(0.8, 1.6, 3.1, 6.3, 12.5, 25.0, 50.0), windowed=True,
    horizontal_direction="cw", horizontal_zero_deg=90.0, vertical_reference="zenith",
    resolution_label="point spacing at 10 m",
    sources=(("pulse_rate_hz", _P50 + ": up to 1,000,000 points/s"),
             ("range_noise_m", _P50 + ": range noise 0.4 mm rms at 10 m, 0.5 mm rms at 50 m"),
             ("step_presets", _P50 + ": point spacing 0.8 / 1.6 / 3.1 / 6.3 / 12.5 / 25 / 50 mm at 10 m"),
             ("theta_fov_deg", _P50 + ": 290 deg vertical (to 55 deg below the horizon)"),
             ("beam_divergence_mrad", _P50 + ": < 0.23 mrad (FWHM)"),
             ("beam_exit_diameter_m", _P50 + ": <= 3.5 mm at the exit (FWHM)"),
             ("max_range_m", _P50 + ": > 1 km"),
             ("max_line_rate_hz", "assumed: 100 mirror turns/s"),
             ("windowed", _P50 + ": field of view set by the user (target and window scans)"),
             ("angles", _THEODOLITE), ("window_overhead_s", _OVERHEAD_SOURCE))))

_RTC = _sheet("Leica RTC360 data sheet")
_add(ScannerProfile(
    name="Leica RTC360", kind="panoramic", pulse_rate_hz=2_000_000.0, range_noise_m=0.0004,
    min_theta_step_deg=math.degrees(math.atan(0.003 / 10)), min_phi_step_deg=math.degrees(math.atan(0.003 / 10)),
    theta_fov_deg=(0.0, 150.0), max_line_rate_hz=200.0, window_overhead_s=60.0,
    beam_divergence_mrad=0.5, beam_exit_diameter_m=0.004, max_range_m=130.0,
    step_presets=_mm_at_10m(3.0, 6.0, 12.0), windowed=False,
    horizontal_direction="cw", horizontal_zero_deg=90.0, vertical_reference="zenith",
    resolution_label="point spacing at 10 m",
    sources=(("pulse_rate_hz", _RTC + ": up to 2,000,000 points/s"),
             ("range_noise_m", _RTC + ": range noise 0.4 mm at 10 m, 0.5 mm at 20 m"),
             ("step_presets", _RTC + ": three resolutions, 3 / 6 / 12 mm at 10 m"),
             ("theta_fov_deg", _RTC + ": 300 deg vertical"),
             ("max_range_m", _RTC + ": 0.5 to 130 m"),
             ("beam_divergence_mrad", "assumed: 0.5 mrad"), ("beam_exit_diameter_m", "assumed: 4 mm"),
             ("max_line_rate_hz", "assumed: 200 mirror turns/s"),
             ("windowed", "assumed: full-dome scans only from the instrument (set \"windowed\": true in a profile "
                          "file if your firmware limits the scan area)"),
             ("window_overhead_s", "assumed: 60 s to start a scan (no window to enter)"),
             ("angles", _THEODOLITE))))

_X7 = _sheet("Trimble X7 data sheet")
_add(ScannerProfile(
    name="Trimble X7", kind="panoramic", pulse_rate_hz=500_000.0, range_noise_m=0.0025,
    min_theta_step_deg=math.degrees(math.atan(0.004 / 10)), min_phi_step_deg=math.degrees(math.atan(0.004 / 10)),
    theta_fov_deg=(0.0, 141.0), max_line_rate_hz=100.0, window_overhead_s=OVERHEAD_S,
    beam_divergence_mrad=0.3, beam_exit_diameter_m=0.006, max_range_m=80.0,
    step_presets=_mm_at_10m(4.0, 6.0, 11.0, 22.0), windowed=True,
    horizontal_direction="cw", horizontal_zero_deg=90.0, vertical_reference="zenith",
    resolution_label="point spacing at 10 m",
    sources=(("pulse_rate_hz", _X7 + ": up to 500,000 points/s"),
             ("range_noise_m", _X7 + ": range noise 2.5 mm (1 sigma) at 10 to 20 m"),
             ("step_presets", _X7 + ": scan densities 4 / 6 / 11 / 22 mm at 10 m"),
             ("theta_fov_deg", _X7 + ": 282 deg vertical"),
             ("max_range_m", _X7 + ": 0.6 to 80 m"),
             ("beam_divergence_mrad", "assumed: 0.3 mrad"), ("beam_exit_diameter_m", "assumed: 6 mm"),
             ("max_line_rate_hz", "assumed: 100 mirror turns/s"),
             ("windowed", "Trimble Perspective: regional scans of a selected area"),
             ("angles", _THEODOLITE), ("window_overhead_s", _OVERHEAD_SOURCE))))

_TX8 = _sheet("Trimble TX8 data sheet")
_add(ScannerProfile(
    name="Trimble TX8", kind="panoramic", pulse_rate_hz=1_000_000.0, range_noise_m=0.002,
    min_theta_step_deg=math.degrees(math.atan(0.0057 / 30)), min_phi_step_deg=math.degrees(math.atan(0.0057 / 30)),
    theta_fov_deg=(0.0, 158.5), max_line_rate_hz=100.0, window_overhead_s=OVERHEAD_S,
    beam_divergence_mrad=0.34, beam_exit_diameter_m=0.006, max_range_m=340.0,
    step_presets=(("Level 3 (5.7 mm @ 30 m)", math.degrees(math.atan(0.0057 / 30))),
                  ("Level 2 (11.3 mm @ 30 m)", math.degrees(math.atan(0.0113 / 30))),
                  ("Level 1 (22.6 mm @ 30 m)", math.degrees(math.atan(0.0226 / 30)))),
    windowed=True, horizontal_direction="cw", horizontal_zero_deg=90.0, vertical_reference="zenith",
    resolution_label="scan level (point spacing at 30 m)",
    sources=(("pulse_rate_hz", _TX8 + ": 1,000,000 points/s"),
             ("range_noise_m", _TX8 + ": range noise < 2 mm at 2 to 120 m"),
             ("step_presets", _TX8 + ": Level 1 / 2 / 3 = 22.6 / 11.3 / 5.7 mm at 30 m"),
             ("theta_fov_deg", _TX8 + ": 317 deg vertical"),
             ("beam_divergence_mrad", _TX8 + ": 0.34 mrad"),
             ("max_range_m", _TX8 + ": 120 m (340 m in extended mode)"),
             ("beam_exit_diameter_m", "assumed: 6 mm"), ("max_line_rate_hz", "assumed: 100 mirror turns/s"),
             ("windowed", _TX8 + ": scan area limits on the panel"),
             ("angles", _THEODOLITE), ("window_overhead_s", _OVERHEAD_SOURCE))))

_FARO = _sheet("FARO Focus Premium tech sheet")
_add(ScannerProfile(
    name="FARO Focus Premium", kind="panoramic", pulse_rate_hz=500_000.0, range_noise_m=0.0003,
    min_theta_step_deg=360.0 / 40_960, min_phi_step_deg=360.0 / 40_960, theta_fov_deg=(0.0, 150.0),
    max_line_rate_hz=97.0, window_overhead_s=OVERHEAD_S, beam_divergence_mrad=0.3,
    beam_exit_diameter_m=0.00212, max_range_m=350.0,
    step_presets=_per_360({"1/1": 40_960, "1/2": 20_480, "1/4": 10_240, "1/5": 8_192, "1/8": 5_120,
                           "1/10": 4_096, "1/16": 2_560, "1/20": 2_048, "1/32": 1_280}),
    windowed=True, horizontal_direction="ccw", vertical_reference="elevation",
    resolution_label="resolution (pts per 360 deg)", quality="4x",
    sources=(("pulse_rate_hz", _FARO + ": up to 2,000,000 points/s; 500,000 assumed at quality 4x, "
                               "the setting for sub-millimetre targets"),
             ("quality", "assumed: 4x (four measurements averaged per point)"),
             ("range_noise_m", _FARO + ": ranging noise 0.3 mm at 10 m, 90 % reflectivity (raw)"),
             ("step_presets", _FARO + ": resolution 1/1 = 40,960 points per 360 deg, down to 1/32"),
             ("theta_fov_deg", _FARO + ": 300 deg vertical"),
             ("max_line_rate_hz", _FARO + ": mirror up to 97 Hz"),
             ("beam_divergence_mrad", _FARO + ": 0.3 mrad (1/e)"),
             ("beam_exit_diameter_m", _FARO + ": 2.12 mm (1/e)"),
             ("max_range_m", _FARO + ": 350 m (Focus Premium 350)"),
             ("windowed", _FARO + ": scan area set by horizontal and vertical limits"),
             ("angles", "FARO panel: horizontal start/end, vertical limits as elevation"),
             ("window_overhead_s", _OVERHEAD_SOURCE))))

_ZF = _sheet("Z+F IMAGER 5016 data sheet")
_add(ScannerProfile(
    name="Z+F IMAGER 5016", kind="panoramic", pulse_rate_hz=1_094_000.0, range_noise_m=0.0003,
    min_theta_step_deg=360.0 / 40_000, min_phi_step_deg=360.0 / 40_000, theta_fov_deg=(0.0, 160.0),
    max_line_rate_hz=55.0, window_overhead_s=OVERHEAD_S, beam_divergence_mrad=0.3,
    beam_exit_diameter_m=0.0035, max_range_m=365.0,
    step_presets=_per_360({"low": 2_500, "middle": 5_000, "high": 10_000, "super high": 20_000,
                           "ultra high": 40_000}),
    windowed=True, horizontal_direction="ccw", vertical_reference="zenith",
    resolution_label="resolution (pixels per 360 deg)", quality="normal",
    sources=(("pulse_rate_hz", _ZF + ": > 1,000,000 points/s (1.094 MHz)"),
             ("range_noise_m", _ZF + ": range noise 0.16 to 0.3 mm rms at 10 m depending on reflectivity"),
             ("quality", "assumed: normal quality, at which the sheet's measurement rate holds"),
             ("step_presets", _ZF + ": resolutions from 2,500 to 40,000 pixels per 360 deg"),
             ("theta_fov_deg", _ZF + ": 320 deg vertical"),
             ("max_line_rate_hz", _ZF + ": 55 rps vertical"),
             ("beam_divergence_mrad", _ZF + ": < 0.3 mrad"),
             ("beam_exit_diameter_m", _ZF + ": about 3.5 mm at 0.1 m"),
             ("max_range_m", _ZF + ": 365 m"),
             ("windowed", _ZF + ": scan area set by horizontal and vertical limits"),
             ("angles", "Z+F LaserControl: horizontal 0-360, vertical from the zenith (check on site)"),
             ("window_overhead_s", _OVERHEAD_SOURCE))))

DEFAULT_SCANNER = "Riegl VZ-1000"


def scanner_names() -> tuple[str, ...]:
    """The catalogue's scanner names, in catalogue order."""
    return tuple(CATALOGUE)


def get_scanner(name_or_file: str) -> ScannerProfile:
    """A catalogue profile by name (case and spaces ignored) or a user profile from a JSON file.

    Raises
    ------
    InputError
        Naming the unknown scanner and listing the catalogue.
    """
    key = "".join(str(name_or_file).lower().split())
    for name, prof in CATALOGUE.items():
        if "".join(name.lower().split()) == key or "".join(name.lower().split()[1:]) == key:
            return prof
    if str(name_or_file).lower().endswith(".json"):
        return load_profile(name_or_file)
    raise InputError(f"unknown scanner {name_or_file!r}; choose one of {', '.join(CATALOGUE)} "
                     "or give a profile file (.json)")


def profile_source(profile: ScannerProfile, field: str) -> str | None:
    """Where a profile's value of ``field`` comes from (a data sheet, the dissertation, "assumed: ..."), or None."""
    return dict(profile.sources).get(field)

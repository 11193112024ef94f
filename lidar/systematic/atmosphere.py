"""The air's refractive index and the range scale it causes.

A scanner turns the time of flight into a range with a refractive index of the air. If it keeps a
standard atmosphere (or is given the wrong one), every range is off by the difference in refractivity:
about -1 ppm per degree Celsius and +0.3 ppm per hectopascal near the ground, tens of ppm over a season.

The group refractivity follows the IAG resolution of 1999 (Rueger, "Refractive index formulae for
radio waves" and the IUGG/IAG working group's formula for light waves, 0.0375 % CO2):

    N_gr = 287.6155 + 4.88660 / lambda^2 + 0.06800 / lambda^4        (lambda in micrometres)
    N    = N_gr * 273.15 / 1013.25 * p / T  -  11.27 e / T           (p, e in hPa, T in K)

with ``e`` the partial pressure of water vapour (from the relative humidity by Magnus' formula). A range
read with the index of ``(T0, p0)`` when the air is ``(T, p)`` reads ``N - N0`` ppm long (a warmer, thinner
air has the smaller index: the instrument's ranges come out short).
"""
from __future__ import annotations

import math

#: The standard atmosphere many instruments assume when given none.
STANDARD_TEMPERATURE_C = 12.0
STANDARD_PRESSURE_HPA = 1013.25
STANDARD_HUMIDITY = 0.6


def group_refractivity_standard(wavelength_nm: float) -> float:
    """Group refractivity (ppm) of standard air (0 degC, 1013.25 hPa, dry) at a wavelength."""
    lam = wavelength_nm / 1000.0
    return 287.6155 + 4.88660 / lam ** 2 + 0.06800 / lam ** 4


def vapour_pressure_hpa(temperature_c: float, relative_humidity: float) -> float:
    """Partial pressure of water vapour (hPa) from the relative humidity (0..1), Magnus' formula."""
    return relative_humidity * 6.1078 * math.exp(17.27 * temperature_c / (temperature_c + 237.3))


def refractivity_ppm(temperature_c: float, pressure_hpa: float = STANDARD_PRESSURE_HPA, *,
                     relative_humidity: float = STANDARD_HUMIDITY, wavelength_nm: float = 1550.0) -> float:
    """Group refractivity ``N = (n - 1) 1e6`` of the air for a ranging laser.

    >>> round(refractivity_ppm(20.0, 1013.25, relative_humidity=0.0) - refractivity_ppm(21.0, 1013.25,
    ...       relative_humidity=0.0), 2)
    0.92
    """
    t_k = temperature_c + 273.15
    e = vapour_pressure_hpa(temperature_c, relative_humidity)
    return group_refractivity_standard(wavelength_nm) * 273.15 / 1013.25 * pressure_hpa / t_k - 11.27 * e / t_k


def range_scale_ppm(temperature_c: float, pressure_hpa: float = STANDARD_PRESSURE_HPA, *,
                    relative_humidity: float = STANDARD_HUMIDITY, wavelength_nm: float = 1550.0,
                    assumed_temperature_c: float = STANDARD_TEMPERATURE_C,
                    assumed_pressure_hpa: float = STANDARD_PRESSURE_HPA,
                    assumed_humidity: float = STANDARD_HUMIDITY) -> float:
    """How many ppm too long a range reads when the instrument assumes one atmosphere and the air is another."""
    actual = refractivity_ppm(temperature_c, pressure_hpa, relative_humidity=relative_humidity,
                              wavelength_nm=wavelength_nm)
    assumed = refractivity_ppm(assumed_temperature_c, assumed_pressure_hpa, relative_humidity=assumed_humidity,
                               wavelength_nm=wavelength_nm)
    return actual - assumed


#: How well the air's readings predict a visit's scale against the baseline's (ppm, one sigma): a temperature logged
#: near the site to about 2 degC (2 ppm) and the pressure, often not logged and taken as standard, to about 8 hPa
#: (2.3 ppm) in each of the two visits' air.
AIR_SCALE_SIGMA_PPM = 3.0


def air_agreement(scale_ppm: float, sigma_ppm: float, predicted_ppm: float) -> tuple[bool, bool]:
    """Whether a measured scale agrees with the air's prediction, and whether it agrees with none at all.

    Both within 3 sigma, the measured scale's sigma and :data:`AIR_SCALE_SIGMA_PPM` together (an instrument that
    corrected for the atmosphere itself leaves none).

    >>> air_agreement(12.0, 4.0, 5.0), air_agreement(1.0, 4.0, 30.0), air_agreement(79.0, 5.0, -5.0)
    ((True, True), (False, True), (False, False))
    """
    s = 3.0 * math.hypot(max(sigma_ppm, 1e-6), AIR_SCALE_SIGMA_PPM)
    return abs(scale_ppm - predicted_ppm) <= s, abs(scale_ppm) <= s

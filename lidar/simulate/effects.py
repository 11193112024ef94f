"""Systematic errors of a real scanner, for the simulator: range walk on retro-reflectors, drift, timing.

Every effect is a small frozen class; all are off unless a visit's
:class:`~lidar.simulate.scene.EpochConditions` names them, and none draws
random numbers.

Return strength
    What a range walk or the receiver's saturation depends on: the power a
    return brings back, relative to a retro-reflective disc filling the beam
    head-on at :data:`STRENGTH_REFERENCE_RANGE_M` (15 m)::

        strength = cover * cos_incidence * (15 m / range) ** 2

    (``cover`` is the fraction of the footprint on the disc). A full disc seen
    head-on at 15 m has strength 1, at 30 m 0.25.

Range walk
    On a retro-reflector the range reads short by ``bias_m(range_m,
    cos_incidence, strength)`` metres (positive = short), growing with the
    return's strength. Forms: :class:`LinearIncidenceWalk`,
    :class:`InverseSquareWalk`, :class:`StrengthStepWalk`,
    :class:`LogisticStrengthWalk`, :class:`ExponentialStrengthWalk`.

Drift
    :class:`DriftModel`: the instrument turns slowly during a visit (tilts about
    its x and y axes, twist about z), each angle linear in the time since the
    visit started plus an optional quadratic term. A point is reported in the
    instrument's frame at the time it was measured.

Timing
    :class:`VisitTiming`: when each point of a visit is measured (the coarse
    scan, then the fine windows in order, each ``gap_s`` after the last).

Intensity
    :class:`IntensityModel`: what the instrument reports as a return's
    intensity. ``mild`` (the default) is the simulator's first model: a
    surface's reflectance with a weak incidence and range factor, targets near
    the top, clipped at 1. ``amplitude`` is a receiver's raw amplitude
    (reflectance times cos(incidence) times (r0 / range)^2, clipped at the
    receiver's ceiling: close concrete and retro-reflectors out to tens of
    metres both saturate); ``db`` is the same amplitude on a logarithmic scale
    (a dB reading mapped onto [0, 1]).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from common.rigid import rotate_vectors

STRENGTH_REFERENCE_RANGE_M = 15.0
INTENSITY_KINDS = ("mild", "amplitude", "db")
ARCSEC = np.pi / (180.0 * 3600.0)  # radians in one arcsecond


def return_strength(range_m: ArrayLike, cos_incidence: ArrayLike, cover: ArrayLike = 1.0) -> np.ndarray:
    """Relative strength of a retro-reflector return (1 for a full disc head-on at 15 m), see the module text.

    Parameters
    ----------
    range_m : (N,) ranges, metres.
    cos_incidence : (N,) |cos| of the incidence angle on the disc.
    cover : (N,) or scalar, fraction of the footprint on the disc. Default 1.

    Returns
    -------
    (N,) float64, dimensionless.
    """
    r = np.asarray(range_m, dtype=np.float64)
    return np.asarray(cover, dtype=np.float64) * np.asarray(cos_incidence, dtype=np.float64) * \
        (STRENGTH_REFERENCE_RANGE_M / np.maximum(r, 1e-3)) ** 2


def _positive(name: str, value: float, *, zero_ok: bool = True) -> None:
    if not np.isfinite(value) or value < 0 or (value == 0 and not zero_ok):
        raise InputError(f"{name} must be {'non-negative' if zero_ok else 'positive'} and finite, got {value}")


@dataclass(frozen=True)
class LinearIncidenceWalk:
    """Range walk linear in the cosine of the incidence angle: ``bias = amplitude_m * cos_incidence``.

    Attributes
    ----------
    amplitude_m : float
        Bias seen head-on (cos = 1), metres, positive = reads short. Default 1 mm.
    """

    amplitude_m: float = 0.001
    form: ClassVar[str] = "linear_incidence"

    def __post_init__(self) -> None:
        if not np.isfinite(self.amplitude_m):
            raise InputError("range walk amplitude must be finite")

    def bias_m(self, range_m: ArrayLike, cos_incidence: ArrayLike, strength: ArrayLike) -> np.ndarray:
        """(N,) range bias, metres (positive: the range reads short)."""
        shape = np.broadcast(np.asarray(range_m), np.asarray(cos_incidence), np.asarray(strength)).shape
        return np.broadcast_to(self.amplitude_m * np.abs(np.asarray(cos_incidence, dtype=np.float64)), shape).copy()


@dataclass(frozen=True)
class InverseSquareWalk:
    """Range walk saturating in 1/range^2: ``bias = max_m * u / (1 + u)``, ``u = cos * (half_range_m / range)^2``.

    Attributes
    ----------
    max_m : float
        Bias approached at very short range, metres. Default 3 mm.
    half_range_m : float
        Range at which a head-on return has half of it, metres. Default 15 m (so 1.5 mm at 15 m head-on).
    """

    max_m: float = 0.003
    half_range_m: float = 15.0
    form: ClassVar[str] = "inverse_square"

    def __post_init__(self) -> None:
        _positive("range walk half range", self.half_range_m, zero_ok=False)
        if not np.isfinite(self.max_m):
            raise InputError("range walk maximum must be finite")

    def bias_m(self, range_m: ArrayLike, cos_incidence: ArrayLike, strength: ArrayLike) -> np.ndarray:
        """(N,) range bias, metres (positive: the range reads short)."""
        r = np.maximum(np.asarray(range_m, dtype=np.float64), 1e-3)
        u = np.abs(np.asarray(cos_incidence, dtype=np.float64)) * (self.half_range_m / r) ** 2
        shape = np.broadcast(r, u, np.asarray(strength)).shape
        return np.broadcast_to(self.max_m * u / (1.0 + u), shape).copy()


@dataclass(frozen=True)
class StrengthStepWalk:
    """Range walk stepping at a strength threshold: ``high_m`` at or above ``threshold``, ``low_m`` below.

    Attributes
    ----------
    high_m, low_m : float
        Bias of strong and of weak returns, metres. Defaults 1.2 mm and 0.2 mm.
    threshold : float
        Return strength of the step. Default 0.5 (a head-on disc at about 21 m).
    """

    high_m: float = 0.0012
    low_m: float = 0.0002
    threshold: float = 0.5
    form: ClassVar[str] = "strength_step"

    def __post_init__(self) -> None:
        _positive("range walk threshold", self.threshold)
        if not (np.isfinite(self.high_m) and np.isfinite(self.low_m)):
            raise InputError("range walk levels must be finite")

    def bias_m(self, range_m: ArrayLike, cos_incidence: ArrayLike, strength: ArrayLike) -> np.ndarray:
        """(N,) range bias, metres (positive: the range reads short)."""
        s = np.asarray(strength, dtype=np.float64)
        shape = np.broadcast(np.asarray(range_m), np.asarray(cos_incidence), s).shape
        return np.broadcast_to(np.where(s >= self.threshold, self.high_m, self.low_m), shape).astype(np.float64)


@dataclass(frozen=True)
class LogisticStrengthWalk:
    """Range walk logistic in strength: ``bias = max_m / (1 + exp(-(strength - midpoint) / width))``.

    Attributes
    ----------
    max_m : float
        Bias of the strongest returns, metres. Default 1.5 mm.
    midpoint : float
        Strength at which the bias is half of it. Default 0.5.
    width : float
        Strength over which it rises (e-folding). Default 0.15.
    """

    max_m: float = 0.0015
    midpoint: float = 0.5
    width: float = 0.15
    form: ClassVar[str] = "logistic_strength"

    def __post_init__(self) -> None:
        _positive("range walk width", self.width, zero_ok=False)
        if not (np.isfinite(self.max_m) and np.isfinite(self.midpoint)):
            raise InputError("range walk parameters must be finite")

    def bias_m(self, range_m: ArrayLike, cos_incidence: ArrayLike, strength: ArrayLike) -> np.ndarray:
        """(N,) range bias, metres (positive: the range reads short)."""
        s = np.asarray(strength, dtype=np.float64)
        shape = np.broadcast(np.asarray(range_m), np.asarray(cos_incidence), s).shape
        z = np.clip((s - self.midpoint) / self.width, -500.0, 500.0)
        return np.broadcast_to(self.max_m / (1.0 + np.exp(-z)), shape).copy()


@dataclass(frozen=True)
class ExponentialStrengthWalk:
    """Range walk saturating exponentially in strength: ``bias = max_m * (1 - exp(-strength / scale))``.

    Attributes
    ----------
    max_m : float
        Bias approached by the strongest returns, metres. Default 1.5 mm.
    scale : float
        Strength scale of the rise. Default 0.5 (a head-on disc at 15 m has 86 % of ``max_m``).
    """

    max_m: float = 0.0015
    scale: float = 0.5
    form: ClassVar[str] = "exponential_strength"

    def __post_init__(self) -> None:
        _positive("range walk scale", self.scale, zero_ok=False)
        if not np.isfinite(self.max_m):
            raise InputError("range walk maximum must be finite")

    def bias_m(self, range_m: ArrayLike, cos_incidence: ArrayLike, strength: ArrayLike) -> np.ndarray:
        """(N,) range bias, metres (positive: the range reads short)."""
        s = np.asarray(strength, dtype=np.float64)
        shape = np.broadcast(np.asarray(range_m), np.asarray(cos_incidence), s).shape
        return np.broadcast_to(self.max_m * (1.0 - np.exp(-np.maximum(s, 0.0) / self.scale)), shape).copy()


RangeWalk = (LinearIncidenceWalk | InverseSquareWalk | StrengthStepWalk | LogisticStrengthWalk
             | ExponentialStrengthWalk)
RANGE_WALK_FORMS: dict[str, type] = {c.form: c for c in (LinearIncidenceWalk, InverseSquareWalk, StrengthStepWalk,
                                                         LogisticStrengthWalk, ExponentialStrengthWalk)}


def walk_to_dict(walk: RangeWalk | None) -> dict | None:
    """``{"form": name, **parameters}`` of a range walk (None for none), for JSON."""
    return None if walk is None else {"form": walk.form, **asdict(walk)}


def walk_from_dict(d: dict | None) -> RangeWalk | None:
    """The range walk written by :func:`walk_to_dict`."""
    if d is None:
        return None
    d = dict(d)
    cls = RANGE_WALK_FORMS.get(str(d.pop("form", "")))
    if cls is None:
        raise InputError(f"unknown range walk form in {d}; known: {', '.join(RANGE_WALK_FORMS)}")
    return cls(**{f.name: float(d[f.name]) for f in fields(cls) if f.name in d})


@dataclass(frozen=True)
class DriftModel:
    """Slow rotation of the instrument during a visit, arcseconds.

    At ``elapsed`` hours since the visit started the instrument's frame is its
    starting frame turned by the rotation vector ``(a_x, a_y, a_z)`` (about its
    own starting x, y and z axes), each ``rate * elapsed + quadratic * elapsed**2``.
    Points are reported in the frame of the moment they are measured.

    Attributes
    ----------
    tilt_x_arcsec_per_h, tilt_y_arcsec_per_h, twist_arcsec_per_h : float
        Linear rates about x, y (tilts) and z (twist). Default 0.
    tilt_x_arcsec_per_h2, tilt_y_arcsec_per_h2, twist_arcsec_per_h2 : float
        Quadratic terms. Default 0.
    jump_x_arcsec, jump_y_arcsec, jump_z_arcsec, jump_after_s : float
        A sudden turn (a knocked tripod, a leg settling) of these angles once ``jump_after_s`` seconds of the
        visit have passed. Default none.
    """

    tilt_x_arcsec_per_h: float = 0.0
    tilt_y_arcsec_per_h: float = 0.0
    twist_arcsec_per_h: float = 0.0
    tilt_x_arcsec_per_h2: float = 0.0
    tilt_y_arcsec_per_h2: float = 0.0
    twist_arcsec_per_h2: float = 0.0
    jump_x_arcsec: float = 0.0
    jump_y_arcsec: float = 0.0
    jump_z_arcsec: float = 0.0
    jump_after_s: float = float("inf")

    def __post_init__(self) -> None:
        if not all(np.isfinite(getattr(self, f.name)) for f in fields(self) if f.name != "jump_after_s"):
            raise InputError("drift rates must be finite")
        if np.isnan(self.jump_after_s):
            raise InputError("the drift's jump time must be a number (inf: no jump)")

    def angles_rad(self, elapsed_s: ArrayLike) -> np.ndarray:
        """(N, 3) rotation vector (about x, y, z of the starting frame), radians, at ``elapsed_s`` seconds."""
        t = np.atleast_1d(np.asarray(elapsed_s, dtype=np.float64))
        h = t / 3600.0
        lin = np.array([self.tilt_x_arcsec_per_h, self.tilt_y_arcsec_per_h, self.twist_arcsec_per_h])
        quad = np.array([self.tilt_x_arcsec_per_h2, self.tilt_y_arcsec_per_h2, self.twist_arcsec_per_h2])
        jump = np.array([self.jump_x_arcsec, self.jump_y_arcsec, self.jump_z_arcsec])
        return (h[:, None] * lin + (h ** 2)[:, None] * quad + (t > self.jump_after_s)[:, None] * jump) * ARCSEC

    def to_start(self, vectors_current: np.ndarray, elapsed_s: ArrayLike) -> np.ndarray:
        """(N, 3) vectors given in the instrument's frame at ``elapsed_s``, expressed in its starting frame."""
        return rotate_vectors(vectors_current, self.angles_rad(elapsed_s))

    def to_current(self, vectors_start: np.ndarray, elapsed_s: ArrayLike) -> np.ndarray:
        """(N, 3) vectors of the starting frame as the instrument reports them at ``elapsed_s`` (inverse of to_start)."""
        return rotate_vectors(vectors_start, -self.angles_rad(elapsed_s))

    def to_dict(self) -> dict:
        d = asdict(self)
        if not np.isfinite(self.jump_after_s):
            d["jump_after_s"] = None  # no jump (JSON has no infinity)
        return d

    @classmethod
    def from_dict(cls, d: dict | None) -> DriftModel | None:
        if d is None:
            return None
        out = {f.name: float(d.get(f.name) or 0.0) for f in fields(cls) if f.name != "jump_after_s"}
        jump_after = d.get("jump_after_s")
        return cls(**out, jump_after_s=float("inf") if jump_after is None else float(jump_after))


@dataclass(frozen=True)
class AxisErrors:
    """The instrument's own errors, which its calibration does not remove: the same at every set-up.

    A beam the instrument reports at zenith angle ``theta`` and azimuth ``phi`` really leaves at zenith
    ``theta + vertical_index`` and azimuth ``phi + collimation / sin(theta) + trunnion * cot(theta)`` (the
    classic axis errors of a theodolite), and every range reads ``range_offset_m`` long (the zero error, on
    every surface, retro-reflective or not).

    Attributes
    ----------
    collimation_arcsec : float
        The beam's deviation from perpendicular to the trunnion axis. Default 0.
    trunnion_arcsec : float
        The trunnion axis' deviation from perpendicular to the vertical axis. Default 0.
    vertical_index_arcsec : float
        A constant error of the zenith angle. Default 0.
    range_offset_m : float
        Added to every range, metres. Default 0.
    """

    collimation_arcsec: float = 0.0
    trunnion_arcsec: float = 0.0
    vertical_index_arcsec: float = 0.0
    range_offset_m: float = 0.0

    def __post_init__(self) -> None:
        if not all(np.isfinite(getattr(self, f.name)) for f in fields(self)):
            raise InputError("axis errors must be finite")
        if max(abs(self.collimation_arcsec), abs(self.trunnion_arcsec), abs(self.vertical_index_arcsec)) > 3600:
            raise InputError("axis errors beyond a degree are not an instrument's")

    def _shift(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(d_theta, d_phi) in radians at zenith angles ``theta`` (radians)."""
        s = np.maximum(np.sin(theta), 1e-6)
        d_phi = (self.collimation_arcsec / s + self.trunnion_arcsec * np.cos(theta) / s) * ARCSEC
        return np.full_like(theta, self.vertical_index_arcsec * ARCSEC), d_phi

    def beam_directions(self, reported: np.ndarray) -> np.ndarray:
        """(N, 3) unit vectors the beams really take, for the (N, 3) directions the instrument reports."""
        theta, phi = _angles(reported)
        d_theta, d_phi = self._shift(theta)
        return _unit(theta + d_theta, phi + d_phi)

    def reported_directions(self, beams: np.ndarray) -> np.ndarray:
        """(N, 3) directions the instrument reports for beams along ``beams`` (the inverse, to 1e-12 rad)."""
        theta, phi = _angles(beams)
        rep_t, rep_p = theta.copy(), phi.copy()
        for _ in range(3):  # fixed point: the shifts are arcseconds
            d_theta, d_phi = self._shift(rep_t)
            rep_t, rep_p = theta - d_theta, phi - d_phi
        return _unit(rep_t, rep_p)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict | None) -> AxisErrors | None:
        return None if d is None else cls(**{f.name: float(d.get(f.name, 0.0)) for f in fields(cls)})


def _angles(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(v, dtype=np.float64)
    return np.arctan2(np.hypot(v[:, 0], v[:, 1]), v[:, 2]), np.arctan2(v[:, 1], v[:, 0])


def _unit(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


@dataclass(frozen=True)
class DeckTransient:
    """Loads crossing the deck during the visit (a train, a lorry, a gust): the deck deflects for seconds.

    Every crossing deflects each span by its own shape (:meth:`BridgeModel.deflection_m`) times a trapezoid in
    time: rising over ``ramp_s`` from ``start_s``, ``amplitude_m`` at midspan (negative: down) for
    ``duration_s - 2 ramp_s``, falling over ``ramp_s``; a train of bogies adds ``wobble`` (a share of the
    amplitude) at ``wobble_hz``. Several crossings (``start_s`` and the others as tuples) add up. The deck
    targets and the deck's surfaces move with it; the truth keeps the static deck (the transient is an error
    of the visit, not a displacement of the bridge).
    """

    start_s: tuple[float, ...]
    duration_s: tuple[float, ...]
    amplitude_m: tuple[float, ...]
    ramp_s: tuple[float, ...] = ()
    wobble: float = 0.0
    wobble_hz: float = 1.5

    def __post_init__(self) -> None:
        for name in ("start_s", "duration_s", "amplitude_m", "ramp_s"):
            v = getattr(self, name)
            object.__setattr__(self, name, tuple(float(x) for x in (v if np.ndim(v) else [v])))
        n = len(self.start_s)
        if not self.ramp_s:
            object.__setattr__(self, "ramp_s", tuple(min(2.0, d / 3) for d in self.duration_s))
        if not (len(self.duration_s) == len(self.amplitude_m) == len(self.ramp_s) == n) or n == 0:
            raise InputError("a deck transient needs as many starts, durations, amplitudes and ramps")
        if not all(np.isfinite(x) for x in (*self.start_s, *self.amplitude_m, self.wobble, self.wobble_hz)) or \
                not all(d > 0 and 0 < r <= d / 2 for d, r in zip(self.duration_s, self.ramp_s, strict=True)):
            raise InputError("a deck transient's times and amplitudes must be finite, its ramps within half its "
                             "duration")

    def factor(self, t_s: ArrayLike) -> np.ndarray:
        """(N,) the midspan deflection (m) at times ``t_s`` (seconds on the visit's clock)."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.zeros(t.shape)
        for t0, dur, amp, ramp in zip(self.start_s, self.duration_s, self.amplitude_m, self.ramp_s, strict=True):
            u = t - t0
            shape = np.clip(np.minimum(u, dur - u) / ramp, 0.0, 1.0)
            wob = 1.0 + self.wobble * np.sin(2 * np.pi * self.wobble_hz * u)
            out += amp * shape * np.where(shape > 0, wob, 0.0)
        return out

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict | None) -> DeckTransient | None:
        if d is None:
            return None
        return cls(tuple(d["start_s"]), tuple(d["duration_s"]), tuple(d["amplitude_m"]), tuple(d.get("ramp_s", ())),
                   float(d.get("wobble", 0.0)), float(d.get("wobble_hz", 1.5)))


@dataclass(frozen=True)
class VisitTiming:
    """When the points of a visit are measured.

    The coarse scan starts at ``start_s``; each fine window starts ``gap_s`` after the previous scan ended (the
    windows in the plan's order, closure windows last). Within a scan the grid directions are measured in order,
    one vertical line (one azimuth) after the other.

    Attributes
    ----------
    start_s : float
        Time of the visit's first point, seconds (any offset: only differences matter). Default 0.
    gap_s : float
        Seconds between the end of one scan and the start of the next (turning to the window). Default 30.
    rate_hz : float, optional
        Measurement rate, points per second. Default None: the scanner profile's pulse rate.
    duration : {"points", "lines"}
        "points": a scan of ``n`` grid directions lasts ``n / rate`` (every direction one measurement).
        "lines": as the instrument spends it (:class:`~lidar.scanner_profile.ScannerProfile`): every vertical
        line costs a full mirror sweep (``sweep / theta_step / rate``, at least one line period), the window's
        own directions measured at the rate from the line's start. Default "points".
    """

    start_s: float = 0.0
    gap_s: float = 30.0
    rate_hz: float | None = None
    duration: str = "points"

    def __post_init__(self) -> None:
        if not np.isfinite(self.start_s):
            raise InputError("visit start time must be finite")
        _positive("gap between windows", self.gap_s)
        if self.rate_hz is not None:
            _positive("measurement rate", self.rate_hz, zero_ok=False)
        if self.duration not in ("points", "lines"):
            raise InputError(f"visit timing duration must be 'points' or 'lines', not {self.duration!r}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict | None) -> VisitTiming | None:
        if d is None:
            return None
        rate = d.get("rate_hz")
        return cls(float(d.get("start_s", 0.0)), float(d.get("gap_s", 30.0)), None if rate is None else float(rate),
                   str(d.get("duration", "points")))


@dataclass(frozen=True)
class IntensityModel:
    """How a return's intensity is formed and reported (see the module text).

    ``mild``: ``reflectance * (0.35 + 0.65 cos)`` on surfaces, ``reflectance * (0.85 + 0.15 cos)`` on
    retro-reflectors, times ``clip(1 - 0.004 range, 0.6, 1)``, plus additive noise (0.012), clipped to [0, 1].

    ``amplitude``: ``a = reflectance * cos * (reference_range_m / range)^2 * (1 + speckle * z)`` (``z`` standard
    normal), the sheet of a retro-reflector ``retro_gain`` times brighter than its reflectance; reported
    ``min(a, 1)`` (1 is the receiver's ceiling). With the defaults, concrete (reflectance 0.24) seen head-on
    saturates closer than 7.8 m (at 10 m it reads 0.6) and a head-on target closer than 77 m.

    ``db``: the same amplitude as ``(10 log10 a - floor_db) / -floor_db``, clipped to [0, 1] (0 dB is the
    ceiling): contrast is compressed, concrete at 15 m reads about 0.9 and a target 1.

    Attributes
    ----------
    kind : {"mild", "amplitude", "db"}
        Default "mild" (the simulator's first model: every earlier scene scans the same).
    reference_range_m : float
        Range at which a head-on return of reflectance 1 reaches the ceiling, metres. Default 16.
    retro_gain : float
        Return of a retro-reflective sheet relative to a diffuse surface of the same reflectance. Default 25.
    speckle : float
        Relative standard deviation of the amplitude (one draw per return). Default 0.05.
    floor_db : float
        Bottom of the dB scale (reported 0), below the ceiling. Default -30 dB.
    """

    kind: str = "mild"
    reference_range_m: float = 16.0
    retro_gain: float = 25.0
    speckle: float = 0.05
    floor_db: float = -30.0

    def __post_init__(self) -> None:
        if self.kind not in INTENSITY_KINDS:
            raise InputError(f"intensity model kind must be one of {', '.join(INTENSITY_KINDS)}, not {self.kind!r}")
        _positive("intensity reference range", self.reference_range_m, zero_ok=False)
        _positive("retro-reflector gain", self.retro_gain, zero_ok=False)
        _positive("intensity speckle", self.speckle)
        if not (np.isfinite(self.floor_db) and self.floor_db < 0):
            raise InputError(f"the dB scale's floor must be negative (below the ceiling), got {self.floor_db}")

    @property
    def mild(self) -> bool:
        return self.kind == "mild"

    def surface(self, reflectance: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
        """(N,) a diffuse surface's return before the range factor."""
        refl = np.asarray(reflectance, dtype=np.float64)
        c = np.abs(np.asarray(cos_incidence, dtype=np.float64))
        return refl * (0.35 + 0.65 * c) if self.mild else refl * c

    def retro(self, reflectance: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
        """(N,) a retro-reflective sheet's return (full cover) before the range factor."""
        refl = np.asarray(reflectance, dtype=np.float64)
        c = np.abs(np.asarray(cos_incidence, dtype=np.float64))
        return refl * (0.85 + 0.15 * c) if self.mild else refl * self.retro_gain * c

    def amplitude(self, value: ArrayLike, range_m: ArrayLike, z: ArrayLike | None = None) -> np.ndarray:
        """(N,) the receiver's amplitude (1 = the ceiling, not clipped) of returns of ``value`` at ``range_m``.

        ``z`` (standard normal draws, one per return) adds the speckle. Not defined for the mild model.
        """
        r = np.maximum(np.asarray(range_m, dtype=np.float64), 1e-3)
        a = np.asarray(value, dtype=np.float64) * (self.reference_range_m / r) ** 2
        if z is not None:
            a = a * np.maximum(1.0 + self.speckle * np.asarray(z, dtype=np.float64), 0.0)
        return a

    def report(self, value: ArrayLike, range_m: ArrayLike, z: ArrayLike) -> np.ndarray:
        """(N,) reported intensities in [0, 1] of returns of ``value`` (surface or retro) at ``range_m``.

        ``z``: one standard normal draw per return (the mild model's additive noise is 0.012 z).
        """
        v = np.asarray(value, dtype=np.float64)
        if self.mild:
            r = np.asarray(range_m, dtype=np.float64)
            out = v * np.clip(1.0 - 0.004 * r, 0.6, 1.0) + 0.012 * np.asarray(z, dtype=np.float64)
            return np.clip(out, 0.0, 1.0)
        a = self.amplitude(v, range_m, z)
        if self.kind == "amplitude":
            return np.minimum(a, 1.0)
        with np.errstate(divide="ignore"):
            db = 10.0 * np.log10(np.maximum(a, 1e-12))
        return np.clip((db - self.floor_db) / -self.floor_db, 0.0, 1.0)

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict | None) -> IntensityModel | None:
        if d is None:
            return None
        return cls(str(d.get("kind", "mild")), **{f.name: float(d[f.name]) for f in fields(cls)
                                                  if f.name != "kind" and f.name in d})

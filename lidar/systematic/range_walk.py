"""The range walk of retro-reflective targets: a range bias that grows with the strength of the return.

A retro-reflector returns far more light than the concrete around it; the receiver saturates and the range
read on the target is biased, usually short, the more so the stronger the return: short ranges and
head-on incidence (Alba, Roncoroni & Scaioni on a Riegl LMS-Z420i; Pesci et al. on an Optech ILRIS). Its
shape differs between instruments and target types and is not known in advance, so the bias is a linear
combination of a few basis functions of the range ``r`` and the cosine of the incidence ``c`` (the return's
strength is taken as ``s = c (r0 / r)^2``, ``r0 = 15 m``), and the campaign's data choose the combination
(:func:`candidate_bases` lists the families tried; :mod:`lidar.systematic.adjustment` selects one by BIC).

A bias ``b`` (metres, positive = the range reads short) moves a centroid toward the scanner along its line
of sight ``u``: the measured position is ``y = p - b u``, corrected by ``p = y + b u``.

A bias proportional to the range is a scale, which every visit's own scale already absorbs: no basis
function is linear in ``r``.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError

#: Prior standard deviation of a range-walk coefficient, mm (the campaign adjustment's and the walk screen's).
PRIOR_BIAS_MM = 2.0
#: Range at which the strength proxy is 1 for a head-on return, metres.
R0_M = 15.0
#: Format version of a range-walk model's JSON form.
RANGE_WALK_FORMAT_VERSION = 1
#: A disc's weaker rim returns (its mixed pixels: part of the beam on the disc) reach down to about this share of
#: its centre's return strength among the returns its range is the mean of (:meth:`RangeWalkModel.smear_m`).
RIM_STRENGTH_SHARE = 0.25
#: Families whose BIC lies within this of the chosen family's are as credible as it (the evidence against them
#: is no more than "positive", Kass & Raftery 1995): a quantity's spread is its largest departure among them.
PLAUSIBLE_BIC = 6.0


def plausible(weights: ArrayLike) -> np.ndarray:
    """Which families (BIC weights ``exp(-dBIC / 2)``, 1 for the chosen one) lie within :data:`PLAUSIBLE_BIC`."""
    return np.asarray(weights, dtype=np.float64) >= np.exp(-0.5 * PLAUSIBLE_BIC) * (1.0 - 1e-9)


def family_spread2(departures: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Variance a quantity carries from the range walk's families: its largest squared departure among the plausible.

    Parameters
    ----------
    departures : (A, ...) array
        The quantity under each alternative family minus under the chosen one (metres, or any unit).
    weights : (A,) array
        The alternatives' BIC weights ``exp(-dBIC / 2)`` (1 for the chosen family).

    Returns
    -------
    (...) array, the unit squared; zero without alternatives.

    Notes
    -----
    A weighted mean of the squared departures would be a model average, right if the families were equally
    likely distinct hypotheses. They are not: many are variants of one shape (a range law with or without a
    constant, saturating or not), and their crowd outweighs the one family that differs, however well it fits.
    On a campaign whose walk is linear in the incidence' cosine, the range laws the data could not tell from
    it put 2.9 % of the along-span movements beyond 3 sigma without a flag (RMS 1.58 sigma); the largest
    departure among the families within ``PLAUSIBLE_BIC`` puts none (RMS 0.94 sigma).
    """
    d = np.asarray(departures, dtype=np.float64)
    keep = plausible(weights)
    return np.max(d[keep] ** 2, axis=0) if keep.any() else np.zeros(d.shape[1:])


def strength(range_m: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
    """The return-strength proxy ``s = c (r0 / r)^2`` (1 for a head-on target at 15 m), shape of the inputs."""
    r = np.maximum(np.asarray(range_m, dtype=np.float64), 0.5)
    return np.clip(np.asarray(cos_incidence, dtype=np.float64), 0.0, 1.0) * (R0_M / r) ** 2


def _r(r) -> np.ndarray:
    return np.maximum(np.asarray(r, dtype=np.float64), 0.5)


#: Basis functions by name: ``f(range_m, cos_incidence) -> values``; all of order 1 for a head-on target at
#: 15 m. Saturating forms level off where the receiver saturates.
FUNCTIONS: dict[str, Callable] = {
    "1": lambda r, c: np.ones_like(_r(r)),
    "cos": lambda r, c: np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0),
    "inv_r2": lambda r, c: np.minimum((R0_M / _r(r)) ** 2, 4.0),
    "sat_r2": lambda r, c: np.minimum((R0_M / _r(r)) ** 2, 1.0),
    "soft_r2": lambda r, c: 1.0 / (1.0 + (_r(r) / R0_M) ** 2) * 2.0,
    "strength": lambda r, c: np.minimum(strength(r, c), 4.0),
    "sat_strength": lambda r, c: np.minimum(strength(r, c), 1.0),
    "soft_strength": lambda r, c: 2.0 * strength(r, c) / (1.0 + strength(r, c)),
    "log_strength": lambda r, c: np.log(np.clip(strength(r, c), 1e-3, 4.0)),
}


#: What a step can be at: the strength, the incidence's cosine or the range's (r0 / r)^2.
STEP_PROXIES: dict[str, Callable] = {
    "s": lambda r, c: strength(r, c),
    "c": lambda r, c: np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0),
    "q": lambda r, c: (R0_M / _r(r)) ** 2,
}


def _step(proxy: str, threshold: float) -> Callable:
    g = STEP_PROXIES[proxy]

    def f(r, c):
        return (g(r, c) > threshold).astype(np.float64)
    return f


def step_name(proxy: str, threshold: float) -> str:
    """The basis-function name of a step of ``proxy`` (s, c or q) at ``threshold``."""
    return f"step_{proxy}@{threshold:.6g}"


def parse_step(name: str) -> tuple[str, float] | None:
    """``(proxy, threshold)`` of a step's basis-function name (:func:`step_name`), None for any other name."""
    if not name.startswith("step_"):
        return None
    proxy, _, value = name[5:].partition("@")
    return proxy, float(value)


def basis_function(name: str) -> Callable:
    """The basis function called ``name`` (``step_s@S`` is a step at strength ``S``, see :func:`step_name`)."""
    step = parse_step(name)
    if step is not None and step[0] in STEP_PROXIES:
        return _step(*step)
    try:
        return FUNCTIONS[name]
    except KeyError:
        raise InputError(f"unknown range-walk basis function {name!r}") from None


#: Each basis function in words (for reports).
WORDS = {"1": "a constant", "cos": "cos(incidence)", "inv_r2": "(r0/range)^2", "sat_r2": "(r0/range)^2 saturating",
         "soft_r2": "a soft (r0/range)^2", "strength": "the return strength", "sat_strength": "the strength, saturating",
         "soft_strength": "the strength, softly saturating", "log_strength": "log(strength)"}
PROXY_WORDS = {"s": "strength", "c": "cos(incidence)", "q": "(r0/range)^2"}


def describe_basis(basis: Sequence[str]) -> str:
    """``a constant + cos(incidence)``; ``a step at strength > 0.42``; ``none`` for an empty basis."""
    words = []
    for b in basis:
        step = parse_step(b)
        if step is not None:
            words.append(f"a step at {PROXY_WORDS.get(step[0], step[0])} > {step[1]:.3g}")
        else:
            words.append(WORDS.get(b, b))
    return " + ".join(words) or "none"


def design(basis: Sequence[str], range_m: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
    """(N, P) values of the basis functions ``basis`` at N returns."""
    r = np.atleast_1d(np.asarray(range_m, dtype=np.float64))
    c = np.atleast_1d(np.asarray(cos_incidence, dtype=np.float64))
    return np.column_stack([basis_function(b)(r, c) for b in basis]) if basis else np.zeros((r.size, 0))


def candidate_bases() -> list[tuple[str, ...]]:
    """The smooth families tried on a campaign: none, one function, a constant plus one function, two shapes.

    Steps at a threshold are screened separately, at every threshold (:mod:`lidar.systematic.walk_screen`).
    """
    shapes = [k for k in FUNCTIONS if k != "1"]
    return [(), ("1",)] + [(k,) for k in shapes] + [("1", k) for k in shapes] + \
        [("cos", "sat_r2"), ("cos", "inv_r2"), ("cos", "soft_r2")]


@dataclass(frozen=True, eq=False)
class RangeWalkModel:
    """A fitted range walk: ``bias_m(r, c) = design(basis, r, c) @ coefficients_m``.

    Attributes
    ----------
    basis : tuple of str
        Basis function names (empty: no range walk).
    coefficients_m : (P,) float64 array, metres
    covariance_m2 : (P, P) float64 array, m^2
    determined : bool
        Whether the campaign's data determine it (False: its sigma is the prior's, see the notes).
    notes : tuple of str
    alternatives : tuple of (basis, coefficients_m, weight)
        Other families the data support about as well (BIC weights, the chosen one included): where
        the plausible ones disagree, :meth:`spread_m` widens the sigma (:func:`family_spread2`).
    """

    basis: tuple[str, ...] = ()
    coefficients_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    covariance_m2: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    determined: bool = True
    notes: tuple[str, ...] = ()
    alternatives: tuple[tuple[tuple[str, ...], np.ndarray, float], ...] = ()

    def bias_m(self, range_m: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
        """Range bias (metres, positive = reads short) at the given returns."""
        return design(self.basis, range_m, cos_incidence) @ self.coefficients_m

    def sigma_m(self, range_m: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
        """Standard deviation of :meth:`bias_m` from the coefficients' covariance, metres."""
        a = design(self.basis, range_m, cos_incidence)
        return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", a, self.covariance_m2, a), 0.0))

    def smear_m(self, range_m: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
        """Standard deviation (metres) of the walk a strength step leaves at a disc whose returns straddle it.

        A step of the return strength acts on each return by its own strength. A disc's rim returns are weaker
        than its centre's (a mixed pixel's beam is partly off the disc), down to about
        :data:`RIM_STRENGTH_SHARE` of it, so a disc whose centre's strength ``s`` is above the threshold ``T``
        but below ``T / RIM_STRENGTH_SHARE`` averages returns on both sides of the step: its walk lies between
        the two levels, by a share the law cannot know (a simulated step of 1.5 mm left 0.8 mm along the line of
        sight, 5 sigma, at a deck target just above its threshold). Half the step at ``T``, fading to nothing
        at ``T / RIM_STRENGTH_SHARE`` on a log scale; zero below ``T`` and for every other family.
        """
        r = np.atleast_1d(np.asarray(range_m, dtype=np.float64))
        s = np.broadcast_to(strength(r, cos_incidence), r.shape)
        out = np.zeros(r.shape)
        for name, coef in zip(self.basis, self.coefficients_m, strict=False):
            step = parse_step(name)
            if step is None or step[0] != "s":
                continue
            x = np.log(np.maximum(s, 1e-12) / step[1]) / np.log(1.0 / RIM_STRENGTH_SHARE)
            out = np.hypot(out, 0.5 * abs(float(coef)) * np.where((x > 0) & (x < 1), 1.0 - x, 0.0))
        return out

    def spread_m(self, range_m: ArrayLike, cos_incidence: ArrayLike) -> np.ndarray:
        """Spread (metres) of the bias among the families the data support (:attr:`alternatives`).

        The largest departure from the chosen family's bias among the plausible families (:func:`family_spread2`).
        """
        r = np.atleast_1d(np.asarray(range_m, dtype=np.float64))
        if not self.alternatives:
            return np.zeros(r.size)
        best = self.bias_m(r, cos_incidence)
        w = np.array([a[2] for a in self.alternatives])
        dev = np.array([design(b, r, cos_incidence) @ coef - best for b, coef, _ in self.alternatives])
        return np.sqrt(family_spread2(dev, w))

    def to_json(self) -> dict:
        return {"format_version": RANGE_WALK_FORMAT_VERSION, "basis": list(self.basis),
                "coefficients_mm": (self.coefficients_m * 1e3).tolist(),
                "covariance_mm2": (self.covariance_m2 * 1e6).tolist(), "determined": self.determined,
                "notes": list(self.notes), "strength": f"cos(incidence) * ({R0_M:g} m / range)^2",
                "alternatives": [{"basis": list(b), "coefficients_mm": (c * 1e3).tolist(), "weight": w}
                                 for b, c, w in self.alternatives]}

    @classmethod
    def from_json(cls, d: dict) -> RangeWalkModel:
        if int(d.get("format_version", 1)) > RANGE_WALK_FORMAT_VERSION:
            raise InputError("range-walk model written by a newer BridgeSurvey")
        p = len(d["basis"])
        alts = tuple((tuple(a["basis"]), np.asarray(a["coefficients_mm"], dtype=np.float64) / 1e3, float(a["weight"]))
                     for a in d.get("alternatives", ()))
        return cls(tuple(d["basis"]), np.asarray(d["coefficients_mm"], dtype=np.float64).reshape(p) / 1e3,
                   np.asarray(d["covariance_mm2"], dtype=np.float64).reshape(p, p) / 1e6,
                   bool(d.get("determined", True)), tuple(d.get("notes", ())), alts)

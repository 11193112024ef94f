"""One adjustment of every visit of a campaign: the scanner's systematic errors from what does not move.

Every visit re-measures, from a new station, what does not move: the reference targets' mutual geometry
and the deck targets' across-span coordinates (a deck sags and slides along the span with temperature,
but not sideways). Each centroid ``y`` (the visit's scanner frame) of target ``i`` in visit ``k`` is
modelled as::

    R(omega_k (t - t_k)) (y + b(r, c) u)  =  (1 + kappa_k) (Q_k X_i + d_k)        (reference targets)
    across . Q_k^T (R(omega_k (t - t_k)) (y + b u) / (1 + kappa_k) - d_k)  =  a_i    (deck targets)

with, per visit, a similarity (rotation ``Q_k``, translation ``d_k`` and the atmosphere's scale
``kappa_k``; the baseline's is the identity) and the set-up's drift ``omega_k`` (rotation rates about
the scanner's axes, linear in time); shared by all visits, the reference targets' positions ``X_i`` and
the deck targets' across-span coordinates ``a_i`` in the baseline's frame, and the range walk ``b``
(:mod:`lidar.systematic.range_walk`; ``u`` the line of sight, ``r`` the range, ``c`` the cosine of the
incidence).

It is solved by Gauss-Newton with every visit's own unknowns eliminated first (the normal equations are
block-arrowhead: visits share only the targets and the range walk), weighted by every centroid's
covariance, with weak priors on the range walk, the scale and the drift (so that an undetermined term
keeps the prior's sigma instead of a guess) and a Tukey down-weighting of blocks that do not fit (a
reference target that moved between visits). The range walk's family is chosen by BIC among
:func:`lidar.systematic.range_walk.candidate_bases` and steps at every threshold
(:mod:`lidar.systematic.walk_screen`).
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from common.errors import InputError
from common.rigid import fit_rigid, rotation_from_rotvec, rotations_from_rotvecs, skew
from lidar.displacement import deck_normal
from lidar.reference_motion import across_axis
from lidar.systematic.axes import ARCSEC, PRIOR_AXES_ARCSEC, AxisModel, axis_basis
from lidar.systematic.range_walk import PRIOR_BIAS_MM, RangeWalkModel, design
from lidar.systematic.walk_screen import bias_information, screen_laws

#: Prior standard deviations: scale (ppm), drift (arcsec per hour); the range walk's is range_walk.PRIOR_BIAS_MM.
PRIOR_SCALE_PPM = 300.0
PRIOR_DRIFT_ARCSEC_H = 30.0
#: Added to every centroid covariance: what a centroid's own covariance leaves out (m^2 per axis).
MODEL_FLOOR_M2 = (2e-5) ** 2
#: Tukey's constant on a block's normalised residual.
TUKEY_C = 4.685
#: Range-walk families within this BIC of the best widen the sigma where they disagree ...
ALTERNATIVE_BIC = 10.0
#: ... the best this many of them (a step at every threshold can put hundreds within it).
MAX_ALTERNATIVES = 96
#: Rounds of choosing the range walk's family and the axis errors again on the previous round's final fit
MAX_LAW_ROUNDS = 3
#: Format version of a saved field model (the store's and the campaign's ``bias.json``). 2 adds the instrument's
#: axis errors (``axes``); a version-1 model has none.
FIELD_MODEL_FORMAT_VERSION = 2
#: A scale whose sigma exceeds this is not determined by the reference geometry (ppm).
SCALE_DETERMINED_PPM = 15.0


@dataclass(frozen=True, eq=False)
class Sighting:
    """One centroid as the adjustment sees it.

    Attributes
    ----------
    target : str
    xyz_socs : (3,) float64 array, metres
    cov : (3, 3) float64 array, m^2
    cos_incidence : float
        |cos| of the incidence on the target (its disc normal against the line of sight).
    time_s : float
        When it was scanned (seconds, any origin; only differences within a visit matter); NaN: unknown.
    """

    target: str
    xyz_socs: np.ndarray
    cov: np.ndarray
    cos_incidence: float
    time_s: float = float("nan")


@dataclass(frozen=True, eq=False)
class VisitSightings:
    """Every centroid of one visit (a target may be sighted twice: the plan's closure window).

    ``shifted``, ``shift_axis`` and ``scale_prior_ppm`` state a hypothesis about the visit (a pier that moved
    along the span, :mod:`lidar.systematic.pier_slide`): the reference targets named in ``shifted`` are fitted
    with one shift of their own along ``shift_axis`` (unit, the baseline's frame), and the visit's scale gets the
    prior ``(value, sigma)`` in ppm (the air's) instead of the weak default; ``shift_alternatives`` names the
    targets of other piers that explain the visit about as well (carried into :class:`VisitSystematics`).
    """

    label: str
    sightings: tuple[Sighting, ...]
    shifted: tuple[str, ...] = ()
    shift_axis: np.ndarray | None = None
    scale_prior_ppm: tuple[float, float] | None = None
    shift_alternatives: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class VisitSystematics:
    """One visit's scale and drift as the adjustment found them.

    ``scale_ppm`` is relative to the baseline (ranges read ``1 + scale_ppm 1e-6`` times the baseline's);
    ``drift_arcsec_h`` are the rotation rates about the scanner's x, y (tilt) and z (twist) axes,
    ``time_ref_s`` the time at which the drift correction is zero.
    """

    label: str
    scale_ppm: float = 0.0
    scale_sigma_ppm: float = 0.0
    drift_arcsec_h: np.ndarray = field(default_factory=lambda: np.zeros(3))
    drift_cov: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    time_ref_s: float = 0.0
    timed: bool = False
    scale_determined: bool = True
    left_out: tuple[str, ...] = ()
    alternative_scale_ppm: tuple[float, ...] = ()  # the visit's scale under each of the range walk's alternatives
    misfit: float = 1.0  # RMS normalised residual of the visit's centroids in the adjustment (1: as their sigmas say)
    shifted: tuple[str, ...] = ()  # pier targets fitted with a shift of their own (a pier that moved along the span)
    shift_m: float = 0.0  # that shift, metres along shift_socs
    shift_sigma_m: float = 0.0
    shift_socs: np.ndarray = field(default_factory=lambda: np.zeros(3))  # its unit direction in the visit's frame
    shift_alternatives: tuple[str, ...] = ()  # other piers' targets whose shift explains the visit about as well

    @property
    def drift_sigma_arcsec_h(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.drift_cov), 0.0))

    def to_json(self) -> dict:
        """The visit's scale and drift as JSON (part of :meth:`FieldModel.to_json`); a pier's shift when fitted."""
        out = {"label": self.label, "scale_ppm": self.scale_ppm, "scale_sigma_ppm": self.scale_sigma_ppm,
               "drift_arcsec_h": np.asarray(self.drift_arcsec_h).tolist(),
               "drift_cov": np.asarray(self.drift_cov).tolist(), "time_ref_s": self.time_ref_s, "timed": self.timed,
               "scale_determined": self.scale_determined, "left_out": list(self.left_out),
               "alternative_scale_ppm": list(self.alternative_scale_ppm), "misfit": self.misfit}
        if self.shifted:  # only then: the JSON (and digests) of every other visit stay as they were
            out.update(shifted=list(self.shifted), shift_m=self.shift_m, shift_sigma_m=self.shift_sigma_m,
                       shift_socs=np.asarray(self.shift_socs).tolist(),
                       shift_alternatives=list(self.shift_alternatives))
        return out

    @classmethod
    def from_json(cls, d: Mapping) -> VisitSystematics:
        """The inverse of :meth:`to_json`."""
        return cls(d["label"], float(d["scale_ppm"]), float(d["scale_sigma_ppm"]),
                   np.asarray(d["drift_arcsec_h"], dtype=float), np.asarray(d["drift_cov"], dtype=float),
                   float(d["time_ref_s"]), bool(d["timed"]), bool(d["scale_determined"]), tuple(d.get("left_out", ())),
                   tuple(float(x) for x in d.get("alternative_scale_ppm", ())), float(d.get("misfit", 1.0)),
                   tuple(d.get("shifted", ())), float(d.get("shift_m", 0.0)), float(d.get("shift_sigma_m", 0.0)),
                   np.asarray(d.get("shift_socs", (0.0, 0.0, 0.0)), dtype=float),
                   tuple(d.get("shift_alternatives", ())))


@dataclass(frozen=True, eq=False)
class FieldModel:
    """The campaign's systematic errors: the range walk, the instrument's axis errors, every visit's scale and drift."""

    baseline: str
    range_walk: RangeWalkModel
    visits: Mapping[str, VisitSystematics]
    sigma0: float = 1.0
    n_observations: int = 0
    notes: tuple[str, ...] = ()
    axes: AxisModel = field(default_factory=AxisModel)

    def visit(self, label: str) -> VisitSystematics:
        return self.visits.get(label) or VisitSystematics(label)

    def to_json(self) -> dict:
        """The model as the versioned JSON of the campaign's ``bias.json`` (:data:`FIELD_MODEL_FORMAT_VERSION`)."""
        return {"format_version": FIELD_MODEL_FORMAT_VERSION, "baseline": self.baseline,
                "range_walk": self.range_walk.to_json(), "sigma0": self.sigma0, "n_observations": self.n_observations,
                "notes": list(self.notes), "visits": [v.to_json() for v in self.visits.values()],
                "axes": self.axes.to_json()}

    @classmethod
    def from_json(cls, d: Mapping) -> FieldModel:
        """The inverse of :meth:`to_json`; a version-1 model has no axis errors, a newer version is an error."""
        if int(d.get("format_version", 1)) > FIELD_MODEL_FORMAT_VERSION:
            raise InputError("the campaign's field model was written by a newer BridgeSurvey")
        visits = {v["label"]: VisitSystematics.from_json(v) for v in d.get("visits", ())}
        return cls(d["baseline"], RangeWalkModel.from_json(d["range_walk"]), visits, float(d.get("sigma0", 1.0)),
                   int(d.get("n_observations", 0)), tuple(d.get("notes", ())), AxisModel.from_json(d.get("axes")))

    def digest(self) -> str:
        """A digest of the whole model (what the store keeps beside it), 24 hex digits."""
        return hashlib.sha256(json.dumps(self.to_json(), sort_keys=True).encode()).hexdigest()[:24]


@dataclass
class _Visit:
    label: str
    refs: list  # (Sighting, target index)
    decks: list  # (Sighting, deck index)
    timed: bool
    t_ref: float
    q: np.ndarray = field(default_factory=lambda: np.eye(3))
    d: np.ndarray = field(default_factory=lambda: np.zeros(3))
    kappa_ppm: float = 0.0
    omega: np.ndarray = field(default_factory=lambda: np.zeros(3))  # arcsec per hour
    weights: dict = field(default_factory=dict)  # (kind, j) -> IRLS weight
    arrays: dict = field(default_factory=dict)  # what does not change between iterations
    shift_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # refs (rows of refs) that shifted
    shift_axis: np.ndarray = field(default_factory=lambda: np.zeros(3))  # unit, baseline frame
    shift_mm: float = 0.0
    scale_prior: tuple[float, float] | None = None  # (ppm, sigma ppm); None: the weak default
    shift_alternatives: tuple[str, ...] = ()

    @property
    def shifts(self) -> bool:
        return bool(self.shift_rows.size) and not self.is_base

    @property
    def n_local(self) -> int:
        return (0 if self.is_base else 7) + (3 if self.timed else 0) + (1 if self.shifts else 0)

    is_base: bool = False


def drift_rotation(omega_arcsec_h: np.ndarray, dt_s: float) -> np.ndarray:
    """(3, 3) rotation of a set-up drifting at ``omega_arcsec_h`` (arcsec per hour about x, y, z) for ``dt_s`` s."""
    return rotation_from_rotvec(np.asarray(omega_arcsec_h) * ARCSEC * dt_s / 3600.0)


def _whiten(cov: np.ndarray) -> np.ndarray:
    """L^-1 with L L^T = cov + floor."""
    return np.linalg.inv(np.linalg.cholesky(cov + MODEL_FLOOR_M2 * np.eye(3)))


class AdjustmentProblem:
    """The unknowns, their ordering and the linearised equations of one adjustment."""

    def __init__(self, visits: Sequence[VisitSightings], groups: Mapping[str, str], basis: tuple[str, ...],
                 start: AdjustmentProblem | None = None, drift: bool = True, axes: tuple[int, ...] = ()):
        self.basis = basis
        self.drift = drift
        self.axes, self.n_axes = tuple(axes), len(axes)  # the instrument's axis errors fitted (AXIS_NAMES)
        base = visits[0]
        ref_ids = sorted({s.target for v in visits for s in v.sightings if groups.get(s.target) == "reference"})
        deck_ids = sorted({s.target for v in visits for s in v.sightings if groups.get(s.target) == "measurement"})
        self.ref_ids, self.deck_ids = ref_ids, deck_ids
        b_deck = {s.target: s.xyz_socs for s in base.sightings if s.target in deck_ids}
        self.across: np.ndarray | None = None
        if len(b_deck) >= 3:
            up = deck_normal(np.array(list(b_deck.values())), up=(0.0, 0.0, 1.0))
            self.across = across_axis(np.array(list(b_deck.values())), up)
        if self.across is None:
            deck_ids = self.deck_ids = []
        # shared unknowns: reference targets (3 each), deck targets' across coordinates, axis errors, range walk
        self.n_shared = 3 * len(ref_ids) + len(deck_ids) + self.n_axes + len(basis)
        self.x_ref = np.zeros((len(ref_ids), 3))
        self.a_deck = np.zeros(len(deck_ids))
        self.alpha = np.zeros(self.n_axes)  # arcsec
        self.theta = np.zeros(len(basis))  # mm
        self.visits = [self._visit(v, k == 0, groups) for k, v in enumerate(visits)]
        if start is None:
            self._initialise()
        else:  # the poses, targets and down-weighting of a solved problem on the same visits
            self.x_ref, self.a_deck = start.x_ref.copy(), start.a_deck.copy()
            self.alpha = np.array([start.alpha[start.axes.index(k)] if k in start.axes else 0.0 for k in self.axes])
            for mine, theirs in zip(self.visits, start.visits, strict=False):
                mine.q, mine.d, mine.kappa_ppm = theirs.q.copy(), theirs.d.copy(), theirs.kappa_ppm
                if mine.shifts and theirs.shifts:
                    mine.shift_mm = theirs.shift_mm
                mine.omega = theirs.omega.copy() if mine.timed else np.zeros(3)
                mine.weights = dict(theirs.weights)

    def _visit(self, v: VisitSightings, is_base: bool, groups) -> _Visit:
        times = np.array([s.time_s for s in v.sightings], dtype=np.float64)
        timed = bool(self.drift and np.all(np.isfinite(times)) and times.size and np.ptp(times) > 1.0)
        refs = [(s, self.ref_ids.index(s.target)) for s in v.sightings if s.target in self.ref_ids]
        decks = [(s, self.deck_ids.index(s.target)) for s in v.sightings if s.target in self.deck_ids]
        out = _Visit(v.label, refs, decks, timed, float(np.median(times)) if timed else 0.0, is_base=is_base,
                     scale_prior=None if is_base else v.scale_prior_ppm)
        if v.shifted and v.shift_axis is not None and not is_base:
            out.shift_rows = np.array([j for j, (s, _) in enumerate(refs) if s.target in v.shifted], dtype=int)
            out.shift_axis = np.asarray(v.shift_axis, dtype=np.float64) / np.linalg.norm(v.shift_axis)
            out.shift_alternatives = tuple(v.shift_alternatives)
        return out

    def _initialise(self) -> None:
        base = self.visits[0]
        seen = np.zeros(len(self.ref_ids), bool)
        for s, i in base.refs:
            self.x_ref[i] = s.xyz_socs
            seen[i] = True
        # deck targets' first positions in the baseline's frame: they start a visit sharing fewer than three
        # reference targets with the visits before it (another set-up of a visit: the deck has not moved)
        deck_at = {s.target: s.xyz_socs for s, _ in base.decks}
        for v in self.visits[1:]:
            common = [(self.x_ref[i], s.xyz_socs) for s, i in v.refs if seen[i]]
            if len(common) < 3:
                common += [(deck_at[s.target], s.xyz_socs) for s, _ in v.decks if s.target in deck_at]
            if len(common) >= 3:
                t = fit_rigid(np.array([a for a, _ in common]), np.array([b for _, b in common]))
                v.q, v.d = t.rotation, t.translation
            for s, i in v.refs:
                if not seen[i]:
                    self.x_ref[i] = v.q.T @ (s.xyz_socs - v.d)
                    seen[i] = True
            for s, _ in v.decks:
                deck_at.setdefault(s.target, v.q.T @ (s.xyz_socs - v.d))
        if self.across is not None:
            got = np.zeros(len(self.deck_ids), bool)
            for v in self.visits:
                for s, m in v.decks:
                    if not got[m]:
                        self.a_deck[m] = self.across @ (v.q.T @ (s.xyz_socs - v.d))
                        got[m] = True

    # ---------------------------------------------------------------- equations of one visit
    def _prepare(self, v: _Visit) -> None:
        """Per-visit arrays that do not change between iterations (positions, whitening, basis values)."""
        sights = [s for s, _ in v.refs] + [s for s, _ in v.decks]
        y = np.array([s.xyz_socs for s in sights], dtype=np.float64).reshape(-1, 3)
        r = np.linalg.norm(y, axis=1)
        c = np.array([s.cos_incidence for s in sights], dtype=np.float64)
        t = np.array([s.time_s for s in sights], dtype=np.float64)
        v.arrays = {
            "y": y, "u": y / r[:, None], "phi": design(self.basis, r, c),
            "dt": np.where(np.isfinite(t), t - v.t_ref, 0.0) if v.timed else np.zeros(len(sights)),
            "lw": np.array([_whiten(s.cov) for s, _ in v.refs]).reshape(-1, 3, 3),
            "cov_deck": np.array([s.cov for s, _ in v.decks]).reshape(-1, 3, 3),
            "ref_idx": np.array([i for _, i in v.refs], dtype=int),
            "deck_idx": np.array([m for _, m in v.decks], dtype=int),
            "axes": axis_basis(y)[:, :, list(self.axes)],
        }

    def _corrected(self, v: _Visit) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(z (n, 3), dz/dtheta (n, 3, P), dz/domega (n, 3, 3), dz/dalpha (n, 3, A)) of every sighting."""
        a = v.arrays
        w = a["y"] + 1e-3 * (a["phi"] @ self.theta)[:, None] * a["u"] + a["axes"] @ self.alpha
        k = ARCSEC * a["dt"] / 3600.0
        rot = rotations_from_rotvecs(v.omega[None, :] * k[:, None])
        z = np.einsum("nij,nj->ni", rot, w)
        dz_dtheta = np.einsum("nij,nj,np->nip", rot, a["u"], a["phi"]) * 1e-3
        dz_domega = -skew(z) * k[:, None, None]
        return z, dz_dtheta, dz_domega, np.einsum("nij,njk->nik", rot, a["axes"])

    def visit_rows(self, v: _Visit) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
        """Whitened (rows x local), (rows x shared) Jacobians and residuals of one visit, and its blocks."""
        if not v.arrays:
            self._prepare(v)
        a = v.arrays
        nl, ns, nb = v.n_local, self.n_shared, len(self.basis)
        nr, nd = len(v.refs), len(v.decks)
        sc = 1.0 + 1e-6 * v.kappa_ppm
        off_w = 0 if v.is_base else 7
        z, dth, dom, dal = self._corrected(v)
        blocks = [("r", j, 3) for j in range(nr)] + [("d", j, 1) for j in range(nd)]
        lw, qa, wt = self.row_weights(v)
        # reference targets: 3 rows each (a shifted pier's at their positions moved along its axis)
        x = self.x_ref[a["ref_idx"]]
        if v.shifts:
            x = x.copy()
            x[v.shift_rows] += 1e-3 * v.shift_mm * v.shift_axis
        qx = x @ v.q.T
        e = z[:nr] - sc * (qx + v.d)
        al = np.zeros((nr, 3, nl))
        if not v.is_base:
            al[:, :, 0:3] = sc * skew(qx) * 1e-3
            al[:, :, 3:6] = -sc * np.eye(3)
            al[:, :, 6] = -(qx + v.d) * 1e-6
        if v.timed:
            al[:, :, off_w:off_w + 3] = dom[:nr]
        if v.shifts:
            al[v.shift_rows, :, nl - 1] = -sc * (v.q @ v.shift_axis) * 1e-3
        ash = np.zeros((nr, 3, ns))
        for j, i in enumerate(a["ref_idx"]):
            ash[j, :, 3 * i:3 * i + 3] = -sc * v.q
        if nb:
            ash[:, :, ns - nb:] = dth[:nr]
        if self.n_axes:
            ash[:, :, self.axis_columns] = dal[:nr]
        jl = [np.einsum("nij,njk->nik", lw, al).reshape(3 * nr, nl)]
        js = [np.einsum("nij,njk->nik", lw, ash).reshape(3 * nr, ns)]
        res = [np.einsum("nij,nj->ni", lw, e).reshape(-1)]
        # deck targets: 1 row each, across the span
        if nd:
            zz = z[nr:]
            vv = zz / sc - v.d
            ed = vv @ qa - self.a_deck[a["deck_idx"]]
            ald = np.zeros((nd, nl))
            if not v.is_base:
                ald[:, 0:3] = np.cross(qa[None, :], vv) * 1e-3
                ald[:, 3:6] = -qa
                ald[:, 6] = -(zz @ qa) / sc ** 2 * 1e-6
            if v.timed:
                ald[:, off_w:off_w + 3] = np.einsum("i,nij->nj", qa, dom[nr:]) / sc
            asd = np.zeros((nd, ns))
            asd[np.arange(nd), 3 * len(self.ref_ids) + a["deck_idx"]] = -1.0
            if nb:
                asd[:, ns - nb:] = np.einsum("i,nip->np", qa, dth[nr:]) / sc
            if self.n_axes:
                asd[:, self.axis_columns] = np.einsum("i,nip->np", qa, dal[nr:]) / sc
            jl.append(ald * wt[:, None])
            js.append(asd * wt[:, None])
            res.append(ed * wt)
        # priors on the visit's scale (ppm) and drift (arcsec/h)
        if not v.is_base:
            centre, sd = v.scale_prior if v.scale_prior is not None else (0.0, PRIOR_SCALE_PPM)
            row = np.zeros((1, nl))
            row[0, 6] = 1.0 / sd
            jl.append(row)
            js.append(np.zeros((1, ns)))
            res.append(np.array([(v.kappa_ppm - centre) / sd]))
        if v.timed:
            rows = np.zeros((3, nl))
            rows[:, off_w:off_w + 3] = np.eye(3) / PRIOR_DRIFT_ARCSEC_H
            jl.append(rows)
            js.append(np.zeros((3, ns)))
            res.append(v.omega / PRIOR_DRIFT_ARCSEC_H)
        return np.vstack(jl), np.vstack(js), np.concatenate(res), blocks

    @property
    def axis_columns(self) -> slice:
        """Where the axis errors sit among the shared unknowns (after the targets', before the range walk's)."""
        start = 3 * len(self.ref_ids) + len(self.deck_ids)
        return slice(start, start + self.n_axes)

    def row_weights(self, v: _Visit) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How a visit's rows are whitened, the blocks' down-weighting included.

        Returns the reference rows' whitening (nr, 3, 3), the across axis in the visit's frame (3,) and the deck
        rows' weights (nd,).
        """
        if not v.arrays:
            self._prepare(v)
        a = v.arrays
        nr, nd = len(v.refs), len(v.decks)
        wr = np.sqrt(np.array([v.weights.get(("r", j), 1.0) for j in range(nr)]))
        lw = a["lw"] * wr[:, None, None]
        if not nd:
            return lw, np.zeros(3), np.zeros(0)
        qa = v.q @ self.across
        wd = np.array([v.weights.get(("d", j), 1.0) for j in range(nd)])
        var = np.einsum("i,nij,j->n", qa, a["cov_deck"], qa) + MODEL_FLOOR_M2
        return lw, qa, np.sqrt(wd / var)

    def apply_step(self, v: _Visit, dx_local: np.ndarray) -> None:
        if not v.is_base:
            # local: scipy.spatial: 0.07-0.09 s of scanners' and reflector list's start-up (measured)
            from scipy.spatial.transform import Rotation

            v.q = Rotation.from_rotvec(dx_local[0:3] * 1e-3).as_matrix() @ v.q
            v.d = v.d + dx_local[3:6]
            v.kappa_ppm += float(dx_local[6])
        if v.timed:
            off = 0 if v.is_base else 7
            v.omega = v.omega + dx_local[off:off + 3]
        if v.shifts:
            v.shift_mm += float(dx_local[-1])

    def apply_shared(self, dx: np.ndarray) -> None:
        nr = 3 * len(self.ref_ids)
        self.x_ref = self.x_ref + dx[:nr].reshape(-1, 3)
        cols = self.axis_columns
        self.a_deck = self.a_deck + dx[nr:cols.start]
        self.alpha = self.alpha + dx[cols]
        self.theta = self.theta + dx[cols.stop:]

    def priors(self) -> tuple[np.ndarray, np.ndarray, float]:
        """The shared unknowns' priors as normal equations: (diagonal (ns,), right-hand side (ns,), chi2).

        Weak priors on the range walk's coefficients (mm) and the axis errors (arcsec), centred on zero, so
        that an undetermined combination keeps the prior's sigma instead of a guess.
        """
        ns, nb, cols = self.n_shared, len(self.basis), self.axis_columns
        diag, rhs = np.zeros(ns), np.zeros(ns)
        diag[cols] = 1.0 / PRIOR_AXES_ARCSEC ** 2
        diag[ns - nb:] = 1.0 / PRIOR_BIAS_MM ** 2
        rhs[cols] = -self.alpha / PRIOR_AXES_ARCSEC ** 2
        rhs[ns - nb:] = -self.theta / PRIOR_BIAS_MM ** 2
        chi2 = float(np.sum((self.alpha / PRIOR_AXES_ARCSEC) ** 2) + np.sum((self.theta / PRIOR_BIAS_MM) ** 2))
        return diag, rhs, chi2


@dataclass
class _Solution:
    chi2: float  # every row, priors included
    n_rows: int
    n_unknowns: int
    cov_shared: np.ndarray
    cov_local: list
    chi2_data: float = 0.0  # the centroids' rows only, for comparing models
    n_data: int = 0


def _solve_once(p: AdjustmentProblem) -> tuple[_Solution, float]:
    """One Gauss-Newton step with every visit's unknowns eliminated; returns the solution and the step size."""
    ns = p.n_shared
    prior_diag, b_s, chi2 = p.priors()
    n_ss = np.diag(prior_diag)
    parts = []
    n_rows = len(p.basis) + p.n_axes
    chi2_data, n_data = 0.0, 0
    for v in p.visits:
        jl, js, res, blocks = p.visit_rows(v)
        chi2 += float(res @ res)
        n_rows += res.size
        nd = sum(n for _, _, n in blocks)
        chi2_data += float(res[:nd] @ res[:nd])
        n_data += sum(n for kind, j, n in blocks if v.weights.get((kind, j), 1.0) > 0)
        n_ll = jl.T @ jl + 1e-12 * np.eye(v.n_local)
        n_ls = jl.T @ js
        inv_ll = np.linalg.pinv(n_ll) if v.n_local else np.zeros((0, 0))
        b_l = -jl.T @ res
        n_ss += js.T @ js - n_ls.T @ inv_ll @ n_ls
        b_s += -js.T @ res - n_ls.T @ inv_ll @ b_l
        parts.append((inv_ll, n_ls, b_l))
    cov_s = np.linalg.pinv(n_ss)
    dx_s = cov_s @ b_s
    step = float(np.max(np.abs(dx_s))) if dx_s.size else 0.0
    cov_l = []
    for v, (inv_ll, n_ls, b_l) in zip(p.visits, parts, strict=False):
        dx_l = inv_ll @ (b_l - n_ls @ dx_s)
        p.apply_step(v, dx_l)
        k = inv_ll @ n_ls
        cov_l.append(inv_ll + k @ cov_s @ k.T)
        step = max(step, float(np.max(np.abs(dx_l))) if dx_l.size else 0.0)
    p.apply_shared(dx_s)
    n_unk = ns + sum(v.n_local for v in p.visits)
    return _Solution(chi2, n_rows, n_unk, cov_s, cov_l, chi2_data, n_data), step


def _reweight(p: AdjustmentProblem) -> list[tuple[str, str]]:
    """Tukey weights of every block from its normalised residual; returns the (visit, target) left out."""
    out = []
    for v in p.visits:
        v.weights = {}
        _, _, res, blocks = p.visit_rows(v)
        pos = 0
        for kind, j, n in blocks:
            rho = float(np.sqrt(np.sum(res[pos:pos + n] ** 2) / n))
            pos += n
            wt = (1 - (rho / TUKEY_C) ** 2) ** 2 if rho < TUKEY_C else 0.0
            v.weights[(kind, j)] = wt
            if wt == 0.0:
                s = (v.refs if kind == "r" else v.decks)[j][0]
                out.append((v.label, s.target))
    return out


def _adjust(p: AdjustmentProblem, *, iterations: int = 8, robust: bool = True) -> tuple[_Solution, list]:
    sol = None
    left_out: list = []
    for it in range(iterations):
        sol, step = _solve_once(p)
        if robust and it in (2, 4, 6):
            left_out = _reweight(p)
        elif step < 1e-7 and it > 6:
            break
    sol, _ = _solve_once(p)  # the covariance at the final point
    return sol, left_out


def _bic(sol: _Solution) -> float:
    """BIC on the centroids' rows (priors left out), for models fitted with the same down-weighting."""
    return sol.chi2_data + math.log(max(sol.n_data, 2)) * sol.n_unknowns


def fit_field_model(visits: Sequence[VisitSightings], groups: Mapping[str, str], *,
                    select_range_walk: bool = True, basis: tuple[str, ...] | None = None) -> FieldModel:
    """The campaign's range walk and every visit's scale and drift, from every visit's centroids.

    The range walk's family is chosen by BIC among the smooth families of
    :func:`lidar.systematic.range_walk.candidate_bases` and a constant plus a step at every threshold of the
    return strength, the incidence's cosine and the range's ``(r0/r)^2`` between the campaign's values: all of
    them screened at once on the adjustment linearised at a general family's solution
    (:mod:`lidar.systematic.walk_screen`), with its down-weighting; the chosen family is then fitted in full.

    Parameters
    ----------
    visits : sequence of VisitSightings
        The baseline first, then every other processed visit (found centroids only).
    groups : mapping target id -> "reference" | "measurement"
    select_range_walk : bool, keyword-only
        Choose the range walk's family (default True); False fits none.
    basis : tuple of str, optional, keyword-only
        Fit this range-walk family without choosing one (quicker: to compare hypotheses about a visit).

    Returns
    -------
    FieldModel
    """
    if not visits:
        raise InputError("the field model needs at least one visit")
    if basis is not None or not select_range_walk or len(visits) < 3:
        p, sol, left = _final_fit(visits, groups, tuple(basis or ()) if select_range_walk else (), None)
        return _model(p, sol, left, visits[0].label)
    general = AdjustmentProblem(visits, groups, ("1", "sat_strength"), axes=(0, 1, 2))
    general_sol, _ = _adjust(general)
    info = bias_information(AdjustmentProblem(visits, groups, (), start=general, axes=(0, 1, 2)))
    chosen = min(screen_laws(info, general_sol.n_data), key=lambda law: law.bic).basis
    tried = []
    while True:  # the law and the axis errors the data support, until the screen agrees with the final fit
        tried.append(chosen)
        p, sol, left = _final_fit(visits, groups, chosen, general)
        # the families screened again on the final fit (its axis errors and drift)
        info = bias_information(AdjustmentProblem(visits, groups, (), start=p, drift=p.drift, axes=p.axes))
        laws = sorted(screen_laws(info, sol.n_data), key=lambda law: law.bic)
        if laws[0].basis in tried or len(tried) >= MAX_LAW_ROUNDS:
            break
        chosen = laws[0].basis
    laws.sort(key=lambda law: (law.basis != chosen, law.bic))
    ref = laws[0].bic
    near = [law for law in laws if law.bic - ref < ALTERNATIVE_BIC][:MAX_ALTERNATIVES]
    alts = tuple((law.basis, law.theta_mm * 1e-3, float(math.exp(-0.5 * (law.bic - ref)))) for law in near)
    scales = [info.scales_ppm(design(law.basis, info.range_m, info.cos_incidence), law.theta_mm) for law in near]
    return _model(p, sol, left, visits[0].label, alts, [[float(k[i]) for k in scales] for i in range(len(visits))])


def _final_fit(visits: Sequence[VisitSightings], groups: Mapping[str, str], basis: tuple[str, ...],
               start: AdjustmentProblem | None) -> tuple[AdjustmentProblem, _Solution, list]:
    """The range walk ``basis`` fitted with the instrument's axis errors and the set-ups' drift the data support.

    All three axis errors are fitted first; the subset BIC prefers follows from that fit's estimates and
    covariance (dropping errors ``S`` raises chi2 by ``a_S^T C_SS^-1 a_S``, their Wald statistic) and is
    fitted again. A drift the data cannot show (no point times, a plan's time model only) is left out by
    BIC too. The fits without start from the full fit's down-weighting (re-weighting would discard the very
    blocks - the closures, the far targets - that show them, and make the model without them look better).
    """
    p = AdjustmentProblem(visits, groups, basis, start=start, axes=(0, 1, 2))
    sol, left = _adjust(p)
    keep = _supported_axes(p, sol)
    best = (p, sol, left)
    if keep != p.axes:
        q = AdjustmentProblem(visits, groups, basis, start=p, axes=keep)
        sol_q, _ = _adjust(q, robust=False)
        best = (q, sol_q, left)
    if any(v.timed for v in best[0].visits):
        q = AdjustmentProblem(visits, groups, basis, start=best[0], axes=keep, drift=False)
        sol_q, _ = _adjust(q, robust=False)
        if _bic(sol_q) < _bic(best[1]):
            best = (q, sol_q, left)
    return best


def _supported_axes(p: AdjustmentProblem, sol: _Solution) -> tuple[int, ...]:
    """The subset of the fitted axis errors BIC prefers, from the full fit's estimates and covariance."""
    cov = sol.cov_shared[p.axis_columns, p.axis_columns]
    per_term = math.log(max(sol.n_data, 2))
    best, best_cost = p.axes, 0.0
    for size in range(p.n_axes):
        for kept in itertools.combinations(range(p.n_axes), size):
            dropped = [i for i in range(p.n_axes) if i not in kept]
            a = p.alpha[dropped]
            wald = float(a @ np.linalg.pinv(cov[np.ix_(dropped, dropped)]) @ a)
            cost = wald - per_term * len(dropped)  # BIC of the smaller model minus the full one's
            if cost < best_cost:
                best, best_cost = tuple(p.axes[i] for i in kept), cost
    return best


def _model(p: AdjustmentProblem, sol: _Solution, left_out: list, baseline: str, alternatives: tuple = (),
           alternative_kappas: list | None = None) -> FieldModel:
    dof = max(sol.n_rows - sol.n_unknowns, 1)
    s0 = math.sqrt(sol.chi2 / dof)
    f = max(1.0, s0) ** 2
    nb = len(p.basis)
    cov_theta = sol.cov_shared[p.n_shared - nb:, p.n_shared - nb:] * f * 1e-6
    determined = bool(nb == 0 or np.all(np.sqrt(np.diag(cov_theta)) * 1e3 < 0.5 * PRIOR_BIAS_MM))
    notes = []
    if not determined:
        notes.append("the campaign's stations are too few or too alike to determine the range walk: its sigma "
                     "is widened to what a plausible bias would cause")
    rw = RangeWalkModel(p.basis, p.theta * 1e-3, cov_theta, determined, tuple(notes), alternatives)
    axes = AxisModel(p.axes, p.alpha.copy(), sol.cov_shared[p.axis_columns, p.axis_columns] * f)
    out = {}
    dof_ratio = max(1.0 - sol.n_unknowns / max(sol.n_rows, 1), 0.1)
    for k, (v, cl) in enumerate(zip(p.visits, sol.cov_local, strict=False)):
        _, _, res, blocks = p.visit_rows(v)
        n_data = sum(n for _, _, n in blocks)
        kept = [(kind, j) for kind, j, _ in blocks if v.weights.get((kind, j), 1.0) > 0]
        misfit = math.sqrt(float(res[:n_data] @ res[:n_data]) / max(n_data, 1) / dof_ratio) if kept else 1.0
        cl = cl * f
        off = 0 if v.is_base else 7
        s_ppm = 0.0 if v.is_base else float(math.sqrt(max(cl[6, 6], 0.0)))
        dcov = cl[off:off + 3, off:off + 3] if v.timed else np.zeros((3, 3))
        left = tuple(t for lab, t in left_out if lab == v.label)
        kappa = 0.0 if v.is_base else v.kappa_ppm
        if alternative_kappas and not v.is_base and alternatives:
            # the range walk's families the data support each imply their own scale: their BIC-weighted mean,
            # with their spread in the sigma (a scale must not hang on one family where several fit)
            w = np.array([a[2] for a in alternatives])
            ks = np.asarray(alternative_kappas[k], dtype=np.float64)
            kappa = float(w @ ks / w.sum())
            s_ppm = float(math.sqrt(s_ppm ** 2 + w @ (ks - kappa) ** 2 / w.sum()))
        shift: dict = {}
        if v.shifts:
            shift = dict(shifted=tuple(sorted({v.refs[j][0].target for j in v.shift_rows})),
                         shift_m=1e-3 * v.shift_mm, shift_sigma_m=1e-3 * float(math.sqrt(max(cl[-1, -1], 0.0))),
                         shift_socs=v.q @ v.shift_axis, shift_alternatives=v.shift_alternatives)
        out[v.label] = VisitSystematics(v.label, kappa, s_ppm,
                                        v.omega.copy() if v.timed else np.zeros(3), dcov, v.t_ref, v.timed,
                                        v.is_base or s_ppm < SCALE_DETERMINED_PPM, left,
                                        tuple(alternative_kappas[k]) if alternative_kappas else (), misfit, **shift)
    return FieldModel(baseline, rw, out, s0, sol.n_rows, tuple(notes), axes)

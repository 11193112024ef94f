"""Ray-cast scanning of the simulated bridge (Open3D), with an intensity and noise model."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from lidar.angles import AngularWindow, bounding_window, direction_from_angles, spherical_from_xyz
from lidar.scan import Scan, normalise_intensity
from lidar.scanner_profile import VZ1000, ScannerProfile
from lidar.simulate.bridge import (
    BridgeModel,
    Target,
    deck_mesh,
    ground_mesh,
    in_plane_axes,
    pier_meshes,
    plate_mesh,
)
from lidar.simulate.effects import (
    AxisErrors,
    DeckTransient,
    DriftModel,
    IntensityModel,
    RangeWalk,
    VisitTiming,
    return_strength,
    walk_to_dict,
)
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth, TargetTruth, WindowTruth

# Surface reflectances (before the incidence and range factors).
REFLECTANCE = {"ground": 0.16, "pier": 0.26, "deck": 0.24, "occluder": 0.20}
TARGET_REFLECTANCE = 0.93
CABLE_TIE_REFLECTANCE = 0.95
INTENSITY_NOISE = 0.012

CABLE_TIE_OFFSET_M = 0.045
CABLE_TIE_SIZE_M = (0.010, 0.050)  # width (radial), length (tangential): a tie with its bright buckle


@dataclass(frozen=True)
class EpochConditions:
    """The state of the bridge, the air and the instrument at one visit.

    Every effect after ``saturated`` is off by default and draws no random numbers.

    Attributes
    ----------
    midspan_displacement_m : float
        Vertical displacement at midspan, positive up (a sag is negative); every span's when
        ``span_displacements_m`` is empty.
    moved_targets : mapping id -> (3,) offset in metres
        Targets knocked or re-glued since the baseline (e.g. a moved reference target).
    occluded : tuple of ids
        Targets hidden behind something placed between them and the scanner.
    cable_ties : tuple of ids
        Targets with a bright cable tie 45 mm from their centre (vertically below
        it on pier faces, along the span under the deck).
    removed : tuple of ids
        Targets that fell off (no disc at all).
    saturated : bool
        Target returns saturate the receiver (intensity clipped at the top).
    span_displacements_m : tuple of float
        Midspan displacement of each span (positive up), one per span. Default (empty): all
        ``midspan_displacement_m``.
    deck_strain : float
        Deck strain along x, dL / L (e.g. 12e-6 /degC times the temperature change): every deck point (the
        deck's mesh and the measurement targets under it) moves along x by ``deck_strain * (x - fixed
        bearing)``; piers and their targets do not. Default 0.
    fixed_bearing_x_m : float, optional
        x of the fixed bearing. Default None: the first pier (x = 0).
    deck_strain_across : float
        Deck strain across the span (its width expanding with the temperature too, dW / W): the deck's mesh and the
        measurement targets under it move sideways by this times their distance from the deck's centreline
        (y = 0). Default 0 (the deck keeps its width).
    range_scale_ppm : float
        Atmosphere: every measured range is multiplied by ``1 + ppm * 1e-6``. Default 0.
    range_scale_rate_ppm_h : float
        The atmosphere changing during the visit (the air warming): the scale at a point's time is
        ``range_scale_ppm + rate * hours since the visit started``. Implies times. Default 0.
    range_walk : RangeWalk, optional
        Bias of retro-reflector (target and cable-tie) ranges, see :mod:`lidar.simulate.effects`. Default none.
    clipped_fraction : float
        Fraction of the target points, the strongest returns, whose raw intensity is clipped at the
        file's ceiling (65535). Default 0.
    drift : DriftModel, optional
        Rotation of the instrument during the visit (points are reported in its frame of the moment). Default
        none. Implies times.
    timing : VisitTiming, optional
        When points are measured; every point then carries a time. Default none (no times, unless drifting:
        then ``VisitTiming()``).
    axis_errors : AxisErrors, optional
        The instrument's uncalibrated axis errors and range zero error (the same instrument's are the same at
        every visit). Default none.
    transient : DeckTransient, optional
        Loads crossing the deck during the visit (a train): the deck and its targets move for seconds while
        points are measured. Implies times. Default none.
    walk_factors : mapping of target id to float, optional
        The range walk of a target's returns times this factor (a weathered or a newer sheet of the same kind
        walks more or less). Default 1 for every target.
    intensity_model : IntensityModel, optional
        How return intensities are formed and reported (a raw amplitude falling as 1/range^2 with a receiver
        ceiling, or on a dB scale). Default none: the mild model (:class:`~lidar.simulate.effects.IntensityModel`
        ``"mild"``).
    pier_shifts : mapping pier index -> (3,) offset in metres, optional
        Piers that moved since the baseline (a pier sliding along the span on its foundation): the pier's box
        and every reference target glued to it move by the offset; the deck, on its bearings, does not. The
        index counts the supports from the first pier (0), as :attr:`BridgeModel.support_x_m`. Default none.
    """

    midspan_displacement_m: float = 0.0
    moved_targets: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    occluded: tuple[str, ...] = ()
    cable_ties: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()
    saturated: bool = False
    span_displacements_m: tuple[float, ...] = ()
    deck_strain: float = 0.0
    fixed_bearing_x_m: float | None = None
    deck_strain_across: float = 0.0
    range_scale_ppm: float = 0.0
    range_scale_rate_ppm_h: float = 0.0
    range_walk: RangeWalk | None = None
    clipped_fraction: float = 0.0
    drift: DriftModel | None = None
    timing: VisitTiming | None = None
    axis_errors: AxisErrors | None = None
    walk_factors: Mapping[str, float] = field(default_factory=dict)
    transient: DeckTransient | None = None
    intensity_model: IntensityModel | None = None
    pier_shifts: Mapping[int, tuple[float, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not np.isfinite(self.midspan_displacement_m):
            raise InputError("midspan displacement must be finite")
        object.__setattr__(self, "walk_factors", MappingProxyType(
            {str(k): float(v) for k, v in dict(self.walk_factors).items()}))
        if not all(np.isfinite(v) and v >= 0 for v in self.walk_factors.values()):
            raise InputError("walk factors must be finite and not negative")
        object.__setattr__(self, "moved_targets", MappingProxyType(
            {k: tuple(float(x) for x in v) for k, v in dict(self.moved_targets).items()}))
        shifts = {int(k): tuple(float(x) for x in v) for k, v in dict(self.pier_shifts).items()}
        if not all(len(v) == 3 and np.all(np.isfinite(v)) and max(map(abs, v)) <= 1.0 for v in shifts.values()):
            raise InputError("epoch conditions: a pier shift must be three finite offsets of at most 1 m")
        object.__setattr__(self, "pier_shifts", MappingProxyType(shifts))
        for name in ("occluded", "cable_ties", "removed"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        object.__setattr__(self, "span_displacements_m", tuple(float(v) for v in self.span_displacements_m))
        scalars = (self.deck_strain, self.deck_strain_across, self.range_scale_ppm, self.range_scale_rate_ppm_h, *self.span_displacements_m,
                   0.0 if self.fixed_bearing_x_m is None else self.fixed_bearing_x_m)
        if not all(np.isfinite(scalars)):
            raise InputError("epoch conditions: strain, range scale (and its rate), span displacements and bearing "
                             "must be finite")
        if max(abs(self.deck_strain), abs(self.deck_strain_across)) > 0.01 or abs(self.range_scale_ppm) > 10_000 or abs(self.range_scale_rate_ppm_h) > 1000:
            raise InputError("epoch conditions: deck strain beyond 1 %, a range scale beyond 10,000 ppm or changing "
                             "faster than 1,000 ppm an hour")
        if not 0.0 <= self.clipped_fraction <= 1.0:
            raise InputError(f"clipped fraction must lie in [0, 1], got {self.clipped_fraction}")

    @property
    def timed(self) -> bool:
        """Whether points get times (a timing, a drift or a scale that changes during the visit is given)."""
        return self.timing is not None or self.drift is not None or self.range_scale_rate_ppm_h != 0.0 or \
            self.transient is not None

    def scale_ppm_at(self, time_s: ArrayLike | None) -> float | np.ndarray:
        """The atmosphere's range scale (ppm) at ``time_s`` (seconds on the visit's clock; None: its start)."""
        if time_s is None or not self.range_scale_rate_ppm_h:
            return self.range_scale_ppm
        return self.range_scale_ppm + self.range_scale_rate_ppm_h * (np.asarray(time_s) - self.visit_timing.start_s) / 3600.0

    @property
    def intensity(self) -> IntensityModel:
        """The intensity model (the mild one when none is given)."""
        return self.intensity_model or _MILD

    @property
    def visit_timing(self) -> VisitTiming:
        return self.timing or VisitTiming()

    @property
    def fixed_x_m(self) -> float:
        """The fixed bearing's x, metres (0, the first pier, by default)."""
        return 0.0 if self.fixed_bearing_x_m is None else float(self.fixed_bearing_x_m)

    def amplitudes(self, n_spans: int) -> float | tuple[float, ...]:
        """What :meth:`BridgeModel.deflection_m` takes: one midspan displacement for all spans, or one per span."""
        if not self.span_displacements_m:
            return self.midspan_displacement_m
        if len(self.span_displacements_m) != n_spans:
            raise InputError(f"epoch conditions give {len(self.span_displacements_m)} span displacements for a "
                             f"bridge of {n_spans} spans")
        return self.span_displacements_m


_MILD = IntensityModel()


@dataclass(frozen=True)
class _Disc:
    target: Target
    centre: np.ndarray  # deformed, bridge frame
    normal: np.ndarray
    radius: float
    displacement: np.ndarray  # (3,) from the undeformed centre


def _overlap(offset, half_size, footprint):
    """Fraction of a footprint of width ``footprint`` centred at ``offset`` covering [-half_size, half_size]."""
    lo = np.maximum(-half_size, offset - footprint / 2)
    hi = np.minimum(half_size, offset + footprint / 2)
    return np.clip((hi - lo) / footprint, 0.0, 1.0)


class _Returns:
    """Rays whose range a retro-reflector (disc or cable tie) set: index, range, cos incidence, cover.

    Collected only when a range walk or clipping needs them; a ray painted twice keeps the last painting,
    as the scan's ranges do.
    """

    def __init__(self) -> None:
        self.parts: list[tuple[np.ndarray, ...]] = []

    def add(self, idx: np.ndarray, range_m: np.ndarray, cos_inc: np.ndarray, cover: np.ndarray) -> None:
        self.parts.append((idx, range_m, cos_inc, cover))

    def final(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(index, range, cos incidence, strength) of every painted ray, once each."""
        if not self.parts:
            e = np.zeros(0)
            return np.zeros(0, np.int64), e, e, e
        idx, r, c, cov = (np.concatenate(a) for a in zip(*self.parts, strict=False))
        _, first_rev = np.unique(idx[::-1], return_index=True)
        last = idx.size - 1 - first_rev
        return idx[last], r[last], c[last], return_strength(r[last], c[last], cov[last])


class BridgeScene:
    """The bridge in one state, seen from one scanner set-up.

    Parameters
    ----------
    model : BridgeModel
    conditions : EpochConditions
    setup : ScannerSetup
        The instrument's pose at the start of the visit (drift turns it from there).
    profile : ScannerProfile, keyword-only
        Noise, footprint and measurement-rate model. Default: Riegl VZ-1000.
    """

    def __init__(self, model: BridgeModel, conditions: EpochConditions, setup: ScannerSetup, *,
                 profile: ScannerProfile = VZ1000):
        # local: open3d costs the application and the campaign commands 0.55-0.85 s of start-up (measured)
        import open3d as o3d

        self.model, self.conditions, self.setup, self.profile = model, conditions, setup, profile
        known = {t.id for t in model.targets}
        for ids in (conditions.occluded, conditions.cable_ties, conditions.removed, tuple(conditions.moved_targets)):
            unknown = set(ids) - known
            if unknown:
                raise InputError(f"epoch conditions name unknown targets: {sorted(unknown)}")
        bad = [k for k in conditions.pier_shifts if not 0 <= k < len(model.support_x_m)]
        if bad:
            raise InputError(f"epoch conditions shift piers {bad}; the bridge has piers 0..{len(model.support_x_m) - 1}")
        self.amplitudes = conditions.amplitudes(model.n_spans)
        self.discs = self._discs()
        self._scene = o3d.t.geometry.RaycastingScene()
        self._kind: dict[int, str] = {}
        self._add("ground", *ground_mesh(model))
        for k, (verts, tris) in enumerate(pier_meshes(model)):
            self._add("pier", verts + np.asarray(conditions.pier_shifts.get(k, (0.0, 0.0, 0.0))), tris)
        self._add("deck", *deck_mesh(model, self.amplitudes, strain=conditions.deck_strain,
                                     strain_across=conditions.deck_strain_across,
                                     fixed_x_m=conditions.fixed_x_m))
        origin = np.asarray(setup.position_m)
        for d in self.discs:
            if d.target.id in conditions.occluded:
                to_scanner = origin - d.centre
                dist = np.linalg.norm(to_scanner)
                self._add("occluder", *plate_mesh(d.centre + to_scanner / dist * min(1.0, 0.3 * dist),
                                                 to_scanner, 0.15))

    def _add(self, kind: str, vertices: np.ndarray, triangles: np.ndarray) -> None:
        # local: open3d costs the application and the campaign commands 0.55-0.85 s of start-up (measured)
        import open3d as o3d

        gid = self._scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)),  # type: ignore[call-overload]
                                        o3d.core.Tensor(triangles.astype(np.uint32)))  # type: ignore[call-overload]
        self._kind[int(gid)] = kind

    def _discs(self) -> list[_Disc]:
        """Every disc still glued on, deformed: measurement targets ride on the deck (deflection and strain)."""
        out = []
        c = self.conditions
        for t in self.model.targets:
            if t.id in c.removed:
                continue
            c0 = np.asarray(t.centre_m)
            disp = np.zeros(3)
            if t.group == "measurement":
                disp[2] = float(self.model.deflection_m(c0[0], self.amplitudes))
                if c.deck_strain:
                    disp[0] = c.deck_strain * (c0[0] - c.fixed_x_m)
                disp[1] = c.deck_strain_across * c0[1]
            else:
                disp += self._pier_shift(c0)
            disp += np.asarray(c.moved_targets.get(t.id, (0.0, 0.0, 0.0)))
            out.append(_Disc(t, c0 + disp, np.asarray(t.normal), t.diameter_m / 2, disp))
        return out

    def _pier_shift(self, centre: np.ndarray) -> np.ndarray:
        """The shift of the pier a reference target at ``centre`` is glued to (zero when that pier did not move)."""
        shifts = self.conditions.pier_shifts
        if not shifts:
            return np.zeros(3)
        supports = np.asarray(self.model.support_x_m)
        k = int(np.argmin(np.abs(supports - centre[0])))
        if abs(supports[k] - centre[0]) > self.model.pier_length_m / 2 + 0.05:
            return np.zeros(3)
        return np.asarray(shifts.get(k, (0.0, 0.0, 0.0)), dtype=np.float64)

    # ------------------------------------------------------------------ timing
    @property
    def rate_hz(self) -> float:
        """Measurement rate of the visit's timing, points per second."""
        return float(self.conditions.visit_timing.rate_hz or self.profile.pulse_rate_hz)

    def _line_seconds(self, window: AngularWindow) -> float:
        p = self.profile
        return max(p.line_sweep_deg / window.theta_step_deg / self.rate_hz, 1.0 / p.max_line_rate_hz)

    def scan_seconds(self, window: AngularWindow) -> float:
        """How long scanning a window takes (see :class:`~lidar.simulate.effects.VisitTiming`), seconds."""
        if self.conditions.visit_timing.duration == "lines":
            return window.shape[1] * self._line_seconds(window)
        return window.n_directions / self.rate_hz

    def ray_times(self, window: AngularWindow, start_s: float) -> np.ndarray:
        """(N,) time of every grid direction of a window (in :meth:`AngularWindow.grid` order), seconds."""
        n = window.n_directions
        if self.conditions.visit_timing.duration == "lines":
            rows = window.shape[0]
            k = np.arange(n)
            return float(start_s) + (k // rows) * self._line_seconds(window) + (k % rows) / self.rate_hz
        return float(start_s) + np.arange(n) / self.rate_hz

    def _world_directions(self, d_socs: np.ndarray, times: np.ndarray | None) -> np.ndarray:
        """(N, 3) bridge-frame directions of rays the instrument sends along ``d_socs`` (its frame of the moment)."""
        axes, drift = self.conditions.axis_errors, self.conditions.drift
        if axes is not None:
            d_socs = axes.beam_directions(d_socs)
        if drift is not None and times is not None:
            d_socs = drift.to_start(d_socs, times - self.conditions.visit_timing.start_s)
        return d_socs @ self.setup.rotation.T

    # ------------------------------------------------------------------ scanning
    def scan(self, window: AngularWindow, *, rng: np.random.Generator, range_noise_m: float | None = None,
             name: str = "", start_s: float | None = None) -> tuple[Scan, ScanTruth]:
        """Scan an angular window; returns the points (SOCS) and the ground truth.

        Parameters
        ----------
        window : AngularWindow
        rng : numpy Generator
            Draws the intensity noise, then the range noise (one each per grid direction).
        range_noise_m : float, keyword-only
            Range standard deviation, metres. Default: the profile's.
        name : str, keyword-only
        start_s : float, keyword-only
            Time of the window's first grid direction, seconds. Default: the visit timing's start when the
            conditions are timed (else no times unless given). Directions are measured in grid order
            (:meth:`ray_times`).

        Returns
        -------
        Scan (with ``time_s`` when timed) and its ScanTruth.
        """
        sigma = self.profile.range_noise_m if range_noise_m is None else float(range_noise_m)
        theta, phi = window.grid()
        d_socs = direction_from_angles(theta, phi)
        if start_s is None and self.conditions.timed:
            start_s = self.conditions.visit_timing.start_s
        times = None if start_s is None else self.ray_times(window, start_s)
        d_world = self._world_directions(d_socs, times)
        origin = np.asarray(self.setup.position_m)
        t, hit, intensity, normals, moves = self._cast(origin, d_world)

        c = self.conditions
        returns = _Returns() if (c.range_walk is not None or c.clipped_fraction > 0) else None
        on_target = np.zeros(len(t), dtype=np.int32) - 1
        counts = {}
        for k, disc in enumerate(self.discs):
            n_on = self._paint_disc(disc, k, origin, d_world, t, hit, intensity, on_target, returns,
                                    surface=(normals, moves))
            counts[disc.target.id] = n_on
            if disc.target.id in c.cable_ties:
                self._paint_cable_tie(disc, origin, d_world, t, hit, intensity, returns)

        if c.transient is not None and times is not None:
            self._move_deck(c.transient, origin, d_world, t, hit, normals, moves, times)
        if c.intensity.mild:
            intensity *= np.clip(1.0 - 0.004 * np.where(hit, t, 0.0), 0.6, 1.0)  # mild range attenuation
            intensity += rng.normal(0.0, INTENSITY_NOISE, len(t))
            np.clip(intensity, 0.0, 1.0, out=intensity)
        else:
            intensity = c.intensity.report(intensity, np.where(hit, t, np.inf), rng.standard_normal(len(t)))
        if c.saturated:
            intensity[on_target >= 0] = 1.0
        rng_noisy = t + rng.normal(0.0, sigma, len(t))
        if returns is not None:
            self._walk_and_clip(returns.final(), on_target, rng_noisy, intensity)
        if c.axis_errors is not None:
            rng_noisy += c.axis_errors.range_offset_m
        if c.range_scale_ppm or c.range_scale_rate_ppm_h:
            rng_noisy *= 1.0 + c.scale_ppm_at(times) * 1e-6
        keep = hit & (rng_noisy > 0)
        xyz = d_socs[keep] * rng_noisy[keep, None]
        raw = np.round(intensity[keep] * 65535.0).astype(np.uint16)
        scan = Scan(
            xyz_socs=np.ascontiguousarray(xyz), intensity=normalise_intensity(raw, (0, 65535)), intensity_raw=raw,
            pose=None, source="", name=name or "simulated",
            metadata={"format": "simulated", "range_noise_m": sigma, "window": window.__dict__.copy()},
            time_s=None if times is None else times[keep],
        )
        if times is None:
            return scan, self.truth(counts)
        when = {d.target.id: float(times[on_target == k].mean()) for k, d in enumerate(self.discs)
                if counts[d.target.id]}
        span = WindowTruth(name or "simulated", float(times[0]), float(times[0]) + self.scan_seconds(window))
        return scan, self.truth(counts, times_s=when, windows=(span,))

    def _move_deck(self, transient: DeckTransient, origin, d_world, t, hit, normals, moves, times) -> None:
        """Ranges of rays on the deck and its targets as the deck stood at each ray's time (a load crossing).

        A surface with normal n moved by u up is met ``u n_z / (n . d)`` further along a ray of direction d.
        """
        sel = np.nonzero(hit & moves)[0]
        if sel.size == 0:
            return
        x = origin[0] + d_world[sel, 0] * t[sel]
        u = transient.factor(times[sel] - self.conditions.visit_timing.start_s) * \
            self.model.deflection_m(x, 1.0)
        n, d = normals[sel], d_world[sel]
        nd = np.einsum("ij,ij->i", n, d)
        ok = np.abs(nd) > 1e-6
        t[sel[ok]] += u[ok] * n[ok, 2] / nd[ok]

    def _cast(self, origin: np.ndarray, d_world: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Cast rays on the meshes.

        Returns (N,) distance along each ray (inf: nothing), hit mask, surface intensity, (N, 3) surface normals
        and whether each ray met the deck.
        """
        # local: open3d costs the application and the campaign commands 0.55-0.85 s of start-up (measured)
        import open3d as o3d

        rays = np.empty((len(d_world), 6), dtype=np.float32)
        rays[:, :3] = origin
        rays[:, 3:] = d_world
        ans = self._scene.cast_rays(o3d.core.Tensor(rays))  # type: ignore[call-overload]
        t = ans["t_hit"].numpy().astype(np.float64)
        gid = ans["geometry_ids"].numpy()
        normals = ans["primitive_normals"].numpy().astype(np.float64)
        del ans, rays
        hit = np.isfinite(t) & (t < self.profile.max_range_m)
        cos_inc = np.abs(np.einsum("ij,ij->i", normals, d_world))
        refl = np.zeros(len(t))
        deck = np.zeros(len(t), dtype=bool)
        for g, kind in self._kind.items():
            sel = gid == g
            refl[sel] = REFLECTANCE[kind]
            deck |= sel & (kind == "deck")
        return t, hit, self.conditions.intensity.surface(refl, cos_inc), normals, deck

    def _walk_and_clip(self, returns: tuple[np.ndarray, ...], on_target: np.ndarray, range_m: np.ndarray,
                       intensity: np.ndarray) -> None:
        """Shorten retro-reflector ranges by the range walk; clip the strongest target returns' intensity."""
        idx, r, cos_inc, strength = returns
        c = self.conditions
        if c.range_walk is not None and idx.size:
            factor = np.ones(len(idx))
            for k, disc in enumerate(self.discs):
                if disc.target.id in c.walk_factors:
                    factor[on_target[idx] == k] = c.walk_factors[disc.target.id]
            range_m[idx] -= c.range_walk.bias_m(r, cos_inc, strength) * factor
        on = on_target[idx] >= 0
        if c.clipped_fraction > 0 and np.any(on):
            limit = np.quantile(strength[on], 1.0 - c.clipped_fraction)
            intensity[idx[on & (strength >= limit)]] = 1.0

    @staticmethod
    def _plane_hits(centre, normal, reach_m: float, origin, d_world, t, hit):
        """Rays that may hit a flat patch glued on the structure.

        Where they meet its plane, and whether it is visible there (facing the scanner, not behind anything the scene
        hit first).

        Returns (candidate ray indices, hit points, distances along the rays, visible, cos incidence).
        """
        to_c = centre - origin
        dist = np.linalg.norm(to_c)
        cand = np.nonzero(d_world @ (to_c / dist) > np.cos(np.arctan2(reach_m, dist)))[0]
        d = d_world[cand]
        denom = d @ normal
        facing = denom < -1e-6
        t_d = np.full(cand.size, np.inf)
        t_d[facing] = (to_c @ normal) / denom[facing]
        t_scene = np.where(hit[cand], t[cand], np.inf)
        visible = facing & (t_d > 0) & (t_d <= t_scene + 0.003)
        q = origin + d * t_d[:, None]
        return cand, q, t_d, visible, np.clip(-denom, 1e-3, 1.0)

    def _paint_disc(self, disc: _Disc, k: int, origin, d_world, t, hit, intensity, on_target,
                    returns: _Returns | None = None, surface: tuple[np.ndarray, np.ndarray] | None = None) -> int:
        reach = disc.radius + 3 * float(self.profile.footprint_m(np.linalg.norm(disc.centre - origin)))
        cand, q, t_d, visible, cos_inc = self._plane_hits(disc.centre, disc.normal, reach, origin, d_world, t, hit)
        if cand.size == 0:
            return 0
        r = np.linalg.norm(q - disc.centre, axis=1)
        fp = self.profile.footprint_m(t_d) / np.sqrt(cos_inc)
        with np.errstate(invalid="ignore"):  # rays that never meet the plane: inf - inf, cleared below
            cover = np.clip((disc.radius + fp / 2 - r) / fp, 0.0, 1.0)
        cover[~visible] = 0.0
        sel = cover > 0
        idx = cand[sel]
        i_target = self.conditions.intensity.retro(TARGET_REFLECTANCE, cos_inc[sel])
        intensity[idx] = cover[sel] * i_target + (1 - cover[sel]) * intensity[idx]
        t[idx] = t_d[sel]
        hit[idx] = True
        on_target[cand[cover >= 0.5]] = k
        if surface is not None:  # a deck target moves with the deck
            surface[0][idx] = disc.normal
            surface[1][idx] = disc.target.group == "measurement"
        if returns is not None:
            returns.add(idx, t_d[sel], cos_inc[sel], cover[sel])
        return int(np.count_nonzero(cover >= 0.5))

    def _paint_cable_tie(self, disc: _Disc, origin, d_world, t, hit, intensity,
                         returns: _Returns | None = None) -> None:
        e1, e2 = in_plane_axes(disc.normal, up_hint=np.array([1.0, 0, 0]) if abs(disc.normal[2]) > 0.9 else None)
        centre = disc.centre - CABLE_TIE_OFFSET_M * e2  # below the target on a pier face
        half_w, half_l = CABLE_TIE_SIZE_M[0] / 2, CABLE_TIE_SIZE_M[1] / 2
        cand, q, t_d, visible, cos_inc = self._plane_hits(centre, disc.normal, half_l + 0.05, origin, d_world, t, hit)
        if cand.size == 0:
            return
        rel = q - centre
        u, v = np.abs(rel @ e2), np.abs(rel @ e1)
        fp = self.profile.footprint_m(t_d)
        cover = _overlap(u, half_w, fp) * _overlap(v, half_l, fp)
        cover[~visible] = 0.0
        sel = cover > 0
        idx = cand[sel]
        model = self.conditions.intensity
        tie = CABLE_TIE_REFLECTANCE if model.mild else model.retro(CABLE_TIE_REFLECTANCE, cos_inc[sel])
        intensity[idx] = np.maximum(intensity[idx], cover[sel] * tie)
        t[idx] = t_d[sel]
        hit[idx] = True
        if returns is not None:
            returns.add(idx, t_d[sel], cos_inc[sel], cover[sel])

    # ------------------------------------------------------------------ truth
    def _target_truth(self, disc: _Disc, points: int | None, time_s: float | None) -> TargetTruth:
        """One target's truth: where it is, how it faces the scanner, and what a noise-free instrument reports."""
        c, tid = self.conditions, disc.target.id
        socs = self.setup.to_socs(disc.centre[None])[0]
        normal_socs = disc.normal @ self.setup.rotation
        rng_m = float(np.linalg.norm(socs))
        cos_inc = float(abs(normal_socs @ socs) / rng_m)
        bias = 0.0 if c.range_walk is None else float(
            c.range_walk.bias_m(rng_m, cos_inc, return_strength(rng_m, cos_inc))[()]) * c.walk_factors.get(tid, 1.0)
        observed = None
        if time_s is not None or c.range_walk is not None or c.range_scale_ppm or c.axis_errors is not None \
                or c.range_scale_rate_ppm_h:
            seen = socs if c.drift is None or time_s is None else \
                c.drift.to_current(socs[None], time_s - c.visit_timing.start_s)[0]
            offset = 0.0
            if c.axis_errors is not None:
                seen = c.axis_errors.reported_directions(seen[None])[0] * rng_m
                offset = c.axis_errors.range_offset_m
            observed = tuple(float(v) for v in
                             seen / rng_m * (rng_m - bias + offset) * (1.0 + float(c.scale_ppm_at(time_s)) * 1e-6))
        return TargetTruth(
            id=tid, group=disc.target.group,
            centre_bridge_m=tuple(disc.centre),
            centre_socs_m=tuple(socs),
            normal_socs=tuple(normal_socs),
            vertical_displacement_m=float(disc.displacement[2]),
            moved=tid in c.moved_targets,
            occluded=tid in c.occluded,
            cable_tie=tid in c.cable_ties,
            points_on_target=points,
            along_span_m=float(disc.displacement[0]) if disc.target.group == "measurement" else 0.0,
            cos_incidence=cos_inc, range_m=rng_m, range_bias_m=bias, time_s=time_s,
            centre_observed_socs_m=observed,
        )

    def truth(self, points_on_target: Mapping[str, int | None] | None = None, *,
              times_s: Mapping[str, float] | None = None, windows: tuple[WindowTruth, ...] = ()) -> ScanTruth:
        """Ground truth of this state and set-up: target centres in both frames and the visit's effects.

        ``times_s`` maps target ids to the time they were scanned; ``windows`` are the visit's scans in order.
        """
        c = self.conditions
        targets = []
        for disc in self.discs:
            tid = disc.target.id
            pts = None if points_on_target is None else int(points_on_target.get(tid) or 0)
            targets.append(self._target_truth(disc, pts, None if times_s is None else times_s.get(tid)))
        amps = self.amplitudes
        return ScanTruth(
            scanner_pose=self.setup.pose, midspan_displacement_m=c.midspan_displacement_m,
            targets=tuple(targets), removed=tuple(c.removed), range_noise_m=self.profile.range_noise_m,
            spans_m=self.model.spans_m,
            span_displacements_m=tuple(float(a) for a in np.broadcast_to(amps, (self.model.n_spans,))),
            deck_strain=c.deck_strain, fixed_bearing_x_m=c.fixed_x_m, range_scale_ppm=c.range_scale_ppm,
            range_walk=walk_to_dict(c.range_walk), clipped_fraction=c.clipped_fraction,
            drift=None if c.drift is None else c.drift.to_dict(),
            timing=c.visit_timing.to_dict() if c.timed else None, windows=windows,
            axis_errors=None if c.axis_errors is None else c.axis_errors.to_dict(),
            range_scale_rate_ppm_h=c.range_scale_rate_ppm_h,
        )

    def coarse_window(self, step_deg: float = 0.05, margin_deg: float = 3.0) -> AngularWindow:
        """A window covering the whole bridge from this set-up, inside the scanner's vertical field of view."""
        m = self.model
        xs = (-m.overhang_m - m.pier_length_m, m.length_m + m.overhang_m + m.pier_length_m)
        ys = (-m.deck_width_m / 2, m.deck_width_m / 2)
        zs = (0.0, m.deck_bottom_m + m.deck_depth_m)
        # Points along every edge of the bounding box: its nearest part may lie mid-span.
        t = np.linspace(0.0, 1.0, 41)
        edges = []
        for a in ((x, y, z) for x in xs for y in ys for z in zs):
            for axis, (lo, hi) in enumerate((xs, ys, zs)):
                e = np.repeat(np.asarray(a, dtype=float)[None], t.size, axis=0)
                e[:, axis] = lo + (hi - lo) * t
                edges.append(e)
        theta, phi, _ = spherical_from_xyz(self.setup.to_socs(np.concatenate(edges)))
        w = bounding_window(theta, phi, margin_deg=margin_deg, theta_step_deg=step_deg, phi_step_deg=step_deg)
        if w is None:
            raise InputError("the bridge is not in view of this set-up")
        lo, hi = self.profile.theta_fov_deg
        return AngularWindow(float(w.phi_min_deg), float(w.phi_max_deg), float(max(lo, w.theta_min_deg)),
                             float(min(hi, w.theta_max_deg)), step_deg, step_deg)

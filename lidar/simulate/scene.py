"""Ray-cast scanning of the simulated bridge (Open3D), with an intensity and noise model."""
from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping, Optional

import numpy as np

from lidar.angles import AngularWindow, bounding_window, direction_from_angles, spherical_from_xyz
from common.errors import InputError
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
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth, TargetTruth

# Surface reflectances (before the incidence and range factors).
REFLECTANCE = {"ground": 0.16, "pier": 0.26, "deck": 0.24, "occluder": 0.20}
TARGET_REFLECTANCE = 0.93
CABLE_TIE_REFLECTANCE = 0.95
INTENSITY_NOISE = 0.012

CABLE_TIE_OFFSET_M = 0.045
CABLE_TIE_SIZE_M = (0.010, 0.050)  # width (radial), length (tangential): a tie with its bright buckle


@dataclass(frozen=True)
class EpochConditions:
    """The state of the bridge at one visit.

    Attributes
    ----------
    midspan_displacement_m : float
        Vertical displacement at midspan, positive up (a sag is negative).
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
    """

    midspan_displacement_m: float = 0.0
    moved_targets: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    occluded: tuple[str, ...] = ()
    cable_ties: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()
    saturated: bool = False

    def __post_init__(self) -> None:
        if not np.isfinite(self.midspan_displacement_m):
            raise InputError("midspan displacement must be finite")
        object.__setattr__(self, "moved_targets", MappingProxyType(
            {k: tuple(float(x) for x in v) for k, v in dict(self.moved_targets).items()}))
        for name in ("occluded", "cable_ties", "removed"):
            object.__setattr__(self, name, tuple(getattr(self, name)))


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


class BridgeScene:
    """The bridge in one state, seen from one scanner set-up.

    Parameters
    ----------
    model : BridgeModel
    conditions : EpochConditions
    setup : ScannerSetup
    profile : ScannerProfile, keyword-only
        Noise and footprint model. Default: Riegl VZ-1000.
    """

    def __init__(self, model: BridgeModel, conditions: EpochConditions, setup: ScannerSetup, *,
                 profile: ScannerProfile = VZ1000):
        import open3d as o3d

        self.model, self.conditions, self.setup, self.profile = model, conditions, setup, profile
        known = {t.id for t in model.targets}
        for ids in (conditions.occluded, conditions.cable_ties, conditions.removed, tuple(conditions.moved_targets)):
            unknown = set(ids) - known
            if unknown:
                raise InputError(f"epoch conditions name unknown targets: {sorted(unknown)}")
        self.discs = self._discs()
        self._scene = o3d.t.geometry.RaycastingScene()
        self._kind: dict[int, str] = {}
        self._add("ground", *ground_mesh(model))
        for mesh in pier_meshes(model):
            self._add("pier", *mesh)
        self._add("deck", *deck_mesh(model, conditions.midspan_displacement_m))
        origin = np.asarray(setup.position_m)
        for d in self.discs:
            if d.target.id in conditions.occluded:
                to_scanner = origin - d.centre
                dist = np.linalg.norm(to_scanner)
                self._add("occluder", *plate_mesh(d.centre + to_scanner / dist * min(1.0, 0.3 * dist),
                                                 to_scanner, 0.15))

    def _add(self, kind: str, vertices: np.ndarray, triangles: np.ndarray) -> None:
        import open3d as o3d

        gid = self._scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)),  # type: ignore[call-overload]
                                        o3d.core.Tensor(triangles.astype(np.uint32)))  # type: ignore[call-overload]
        self._kind[int(gid)] = kind

    def _discs(self) -> list[_Disc]:
        out = []
        for t in self.model.targets:
            if t.id in self.conditions.removed:
                continue
            c0 = np.asarray(t.centre_m)
            disp = np.zeros(3)
            if t.group == "measurement":
                disp[2] = float(self.model.deflection_m(c0[0], self.conditions.midspan_displacement_m))
            disp += np.asarray(self.conditions.moved_targets.get(t.id, (0.0, 0.0, 0.0)))
            out.append(_Disc(t, c0 + disp, np.asarray(t.normal), t.diameter_m / 2, disp))
        return out

    # ------------------------------------------------------------------ scanning
    def scan(self, window: AngularWindow, *, rng: np.random.Generator, range_noise_m: Optional[float] = None,
             name: str = "") -> tuple[Scan, ScanTruth]:
        """Scan an angular window; returns the points (SOCS) and the ground truth."""
        import open3d as o3d

        sigma = self.profile.range_noise_m if range_noise_m is None else float(range_noise_m)
        theta, phi = window.grid()
        d_socs = direction_from_angles(theta, phi)
        rot = self.setup.rotation
        d_world = d_socs @ rot.T
        origin = np.asarray(self.setup.position_m)
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
        for g, kind in self._kind.items():
            sel = gid == g
            refl[sel] = REFLECTANCE[kind]
        intensity = refl * (0.35 + 0.65 * cos_inc)

        on_target = np.zeros(len(t), dtype=np.int32) - 1
        counts = {}
        for k, disc in enumerate(self.discs):
            n_on = self._paint_disc(disc, k, origin, d_world, t, hit, intensity, on_target)
            counts[disc.target.id] = n_on
            if disc.target.id in self.conditions.cable_ties:
                self._paint_cable_tie(disc, origin, d_world, t, hit, intensity)

        intensity *= np.clip(1.0 - 0.004 * np.where(hit, t, 0.0), 0.6, 1.0)  # mild range attenuation
        intensity += rng.normal(0.0, INTENSITY_NOISE, len(t))
        np.clip(intensity, 0.0, 1.0, out=intensity)
        if self.conditions.saturated:
            intensity[on_target >= 0] = 1.0
        rng_noisy = t + rng.normal(0.0, sigma, len(t))
        keep = hit & (rng_noisy > 0)
        xyz = d_socs[keep] * rng_noisy[keep, None]
        raw = np.round(intensity[keep] * 65535.0).astype(np.uint16)
        scan = Scan(
            xyz_socs=np.ascontiguousarray(xyz), intensity=normalise_intensity(raw, (0, 65535)), intensity_raw=raw,
            pose=None, source="", name=name or "simulated",
            metadata={"format": "simulated", "range_noise_m": sigma, "window": window.__dict__.copy()},
        )
        return scan, self.truth(counts)

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

    def _paint_disc(self, disc: _Disc, k: int, origin, d_world, t, hit, intensity, on_target) -> int:
        reach = disc.radius + 3 * float(self.profile.footprint_m(np.linalg.norm(disc.centre - origin)))
        cand, q, t_d, visible, cos_inc = self._plane_hits(disc.centre, disc.normal, reach, origin, d_world, t, hit)
        if cand.size == 0:
            return 0
        r = np.linalg.norm(q - disc.centre, axis=1)
        fp = self.profile.footprint_m(t_d) / np.sqrt(cos_inc)
        cover = np.clip((disc.radius + fp / 2 - r) / fp, 0.0, 1.0)
        cover[~visible] = 0.0
        sel = cover > 0
        idx = cand[sel]
        i_target = TARGET_REFLECTANCE * (0.85 + 0.15 * cos_inc[sel])
        intensity[idx] = cover[sel] * i_target + (1 - cover[sel]) * intensity[idx]
        t[idx] = t_d[sel]
        hit[idx] = True
        on_target[cand[cover >= 0.5]] = k
        return int(np.count_nonzero(cover >= 0.5))

    def _paint_cable_tie(self, disc: _Disc, origin, d_world, t, hit, intensity) -> None:
        e1, e2 = in_plane_axes(disc.normal, up_hint=np.array([1.0, 0, 0]) if abs(disc.normal[2]) > 0.9 else None)
        centre = disc.centre - CABLE_TIE_OFFSET_M * e2  # below the target on a pier face
        half_w, half_l = CABLE_TIE_SIZE_M[0] / 2, CABLE_TIE_SIZE_M[1] / 2
        cand, q, t_d, visible, _ = self._plane_hits(centre, disc.normal, half_l + 0.05, origin, d_world, t, hit)
        if cand.size == 0:
            return
        rel = q - centre
        u, v = np.abs(rel @ e2), np.abs(rel @ e1)
        fp = self.profile.footprint_m(t_d)
        cover = _overlap(u, half_w, fp) * _overlap(v, half_l, fp)
        cover[~visible] = 0.0
        sel = cover > 0
        idx = cand[sel]
        intensity[idx] = np.maximum(intensity[idx], cover[sel] * CABLE_TIE_REFLECTANCE)
        t[idx] = t_d[sel]
        hit[idx] = True

    # ------------------------------------------------------------------ truth
    def truth(self, points_on_target: Optional[Mapping[str, Optional[int]]] = None) -> ScanTruth:
        """Ground truth of this state and set-up: target centres in both frames."""
        targets = []
        for disc in self.discs:
            tid = disc.target.id
            targets.append(TargetTruth(
                id=tid, group=disc.target.group,
                centre_bridge_m=tuple(disc.centre),
                centre_socs_m=tuple(self.setup.to_socs(disc.centre[None])[0]),
                normal_socs=tuple(disc.normal @ self.setup.rotation),
                vertical_displacement_m=float(disc.displacement[2]),
                moved=tid in self.conditions.moved_targets,
                occluded=tid in self.conditions.occluded,
                cable_tie=tid in self.conditions.cable_ties,
                points_on_target=None if points_on_target is None else int(points_on_target.get(tid) or 0),
            ))
        return ScanTruth(
            scanner_pose=self.setup.pose, midspan_displacement_m=self.conditions.midspan_displacement_m,
            targets=tuple(targets), removed=tuple(self.conditions.removed), range_noise_m=self.profile.range_noise_m,
        )

    def coarse_window(self, step_deg: float = 0.05, margin_deg: float = 3.0) -> AngularWindow:
        """A window covering the whole bridge from this set-up, inside the scanner's vertical field of view."""
        m = self.model
        xs = (-m.overhang_m - m.pier_length_m, m.span_m + m.overhang_m + m.pier_length_m)
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

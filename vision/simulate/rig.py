"""A synthetic dual-camera rig: exact projections and rendered images of both targets.

Frames (all metres):

* CS(1), the world here: the sub-camera at the initial frame; x right, y down, z towards the
  sub-target on the pier.
* The main camera sits ``baseline_m`` behind the sub-camera, looking the other way (along -z),
  with a small mounting misalignment, towards the main target at midspan.
* WM: the main target's initial plane; origin at its centre, x to the right and y *up* as seen by
  the main camera, z towards the camera. Target displacements are (x, y) in WM: y is vertical.
* WS: the checkerboard; origin at its first inner corner, x along the rows, y down the columns.

The rig's pose at frame k is ``G_k`` (4x4, body -> CS(1)); the sub-camera motion the method
estimates is ``B_CS(1)->CS(k) = inv(G_k)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike

from vision.geometry import apply, intrinsic_matrix, invert, project_pinhole, rigid, rigid_from_rotvec

# Main camera axes in the rig body: it looks along -z of the sub-camera (back to back).
_R_BODY_TO_MAIN_NOMINAL = np.diag([-1.0, 1.0, -1.0])
# WM axes in CS(1): x_WM = -x, y_WM = -y (up), z_WM = +z (towards the cameras).
_R_WM_TO_WORLD = np.diag([-1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard sub-target: ``squares`` = (columns, rows) of squares, edge ``square_m``."""

    squares: tuple[int, int] = (13, 8)
    square_m: float = 0.008

    @property
    def inner_corners(self) -> tuple[int, int]:
        """(columns, rows) of inner corners, as OpenCV's ``patternSize``."""
        return self.squares[0] - 1, self.squares[1] - 1

    def object_points(self) -> np.ndarray:
        """Inner-corner coordinates in WS, shape (n, 3), row by row (OpenCV's order)."""
        nc, nr = self.inner_corners
        r, c = np.mgrid[0:nr, 0:nc]
        return np.column_stack([c.ravel() * self.square_m, r.ravel() * self.square_m, np.zeros(nc * nr)])

    def colour(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Board reflectance (0 black .. 1 white) at WS points; one white square margin, grey beyond."""
        i = np.floor(x / self.square_m).astype(np.int64) + 1
        j = np.floor(y / self.square_m).astype(np.int64) + 1
        nc, nr = self.squares
        inside = (i >= 0) & (i < nc) & (j >= 0) & (j < nr)
        margin = (i >= -1) & (i <= nc) & (j >= -1) & (j <= nr)
        out = np.where(margin, 0.95, 0.5)
        return np.where(inside, np.where((i + j) % 2 == 0, 0.05, 0.95), out)

    @property
    def centre_ws(self) -> np.ndarray:
        nc, nr = self.inner_corners
        return np.array([(nc - 1) * self.square_m / 2, (nr - 1) * self.square_m / 2, 0.0])


def die_pattern(dx_m: float = 0.015, dy_m: float = 0.011) -> np.ndarray:
    """Five circle centres like the lab target: the centre and four corners, (5, 2) in WM."""
    return np.array([[-dx_m, dy_m], [dx_m, dy_m], [0.0, 0.0], [-dx_m, -dy_m], [dx_m, -dy_m]])


@dataclass(frozen=True)
class RigGeometry:
    """Geometry of the rig and its targets (defaults: the dissertation's numerical study).

    Parameters
    ----------
    main_distance_m, sub_distance_m : camera-to-target distances (main target 10 m from the
        sub-target in total with the 80 mm between the cameras).
    baseline_m : distance between the two camera centres (back to back).
    main_fov_m, sub_fov_m : field-of-view width at the target.
    main_fov_h_m, sub_fov_h_m : field-of-view height at the target; None (default): it follows the
        image's aspect ratio (square pixels). Given, the pixels are not square (``fy != fx``), as a
        200 x 150 mm field on a 16:10 sensor needs.
    resolution : (width, height) in pixels of both cameras.
    main_pattern_m : (N, 2) circle centres in WM; ``circle_radius_m`` their radius.
    board : the sub-target checkerboard.
    main_mount_rotvec : small misalignment of the main camera on the rig (rad).
    """

    main_distance_m: float = 9.82
    sub_distance_m: float = 0.10
    baseline_m: float = 0.08
    main_fov_m: float = 0.20
    sub_fov_m: float = 0.15
    resolution: tuple[int, int] = (1920, 1200)
    main_fov_h_m: float | None = None
    sub_fov_h_m: float | None = None
    main_pattern_m: np.ndarray = field(default_factory=die_pattern)
    circle_radius_m: float = 0.004
    board: Checkerboard = Checkerboard()
    main_mount_rotvec: tuple[float, float, float] = (0.004, -0.006, 0.012)

    @classmethod
    def laboratory(cls) -> RigGeometry:
        """The dissertation's lab: main target 11 m away at 0.08 mm/pixel, sub-target 50 mm at 0.05 mm/pixel."""
        return cls(main_distance_m=11.0, sub_distance_m=0.05, main_fov_m=0.08e-3 * 1920,
                   sub_fov_m=0.05e-3 * 1920, board=Checkerboard((21, 13), 0.004))

    def with_resolution(self, width: int, height: int) -> RigGeometry:

        return replace(self, resolution=(int(width), int(height)))

    @property
    def K_main(self) -> np.ndarray:
        return self._K(self.main_distance_m, self.main_fov_m, self.main_fov_h_m)

    @property
    def K_sub(self) -> np.ndarray:
        return self._K(self.sub_distance_m, self.sub_fov_m, self.sub_fov_h_m)

    def _K(self, distance_m: float, fov_w_m: float, fov_h_m: float | None) -> np.ndarray:
        w, h = self.resolution
        K = intrinsic_matrix(w * distance_m / fov_w_m, w, h)
        if fov_h_m is not None:
            K[1, 1] = h * distance_m / fov_h_m
        return K

    @property
    def B_body_to_main(self) -> np.ndarray:
        R = rigid_from_rotvec(self.main_mount_rotvec, np.zeros(3))[:3, :3] @ _R_BODY_TO_MAIN_NOMINAL
        centre = np.array([0.0, 0.0, -self.baseline_m])
        return rigid(R, -R @ centre)

    @property
    def B_wm_to_world(self) -> np.ndarray:
        # The main target faces the main camera, centred on its optical axis.
        Bm = invert(self.B_body_to_main)
        centre = apply(Bm, np.array([0.0, 0.0, self.main_distance_m]))
        return rigid(_R_WM_TO_WORLD, centre)

    @property
    def B_ws_to_world(self) -> np.ndarray:
        return rigid(np.eye(3), np.array([0.0, 0.0, self.sub_distance_m]) - self.board.centre_ws)

    def main_points_world(self, displacement_m: ArrayLike = (0.0, 0.0)) -> np.ndarray:
        """Circle centres in CS(1) after an in-plane target displacement (dx, dy) in WM, (N, 3)."""
        p = np.column_stack([self.main_pattern_m + np.asarray(displacement_m, float).reshape(1, 2),
                             np.zeros(len(self.main_pattern_m))])
        return apply(self.B_wm_to_world, p)


class SyntheticRig:
    """Both cameras of a :class:`RigGeometry`: exact projections and rendered 8-bit images.

    ``quantise=True`` rounds exact projections to whole pixels (no sub-pixel detection), as in
    the dissertation's numerical study; ``resolution=None`` in :meth:`project` means no
    quantisation at all.
    """

    def __init__(self, geometry: RigGeometry = RigGeometry()):
        self.geometry = geometry

    # ---------------------------------------------------------------- exact projections
    def main_image_points(self, pose: np.ndarray, displacement_m: ArrayLike = (0.0, 0.0), *,
                          quantise: bool = False) -> np.ndarray:
        """(N, 2) image points (u, v) of the main target's circle centres at rig pose ``pose``."""
        g = self.geometry
        body = apply(invert(pose), g.main_points_world(displacement_m))
        uv = project_pinhole(g.K_main, apply(g.B_body_to_main, body))
        return np.round(uv) if quantise else uv

    def sub_image_points(self, pose: np.ndarray, *, quantise: bool = False) -> np.ndarray:
        """(M, 2) image points of the checkerboard's inner corners at rig pose ``pose``."""
        g = self.geometry
        world = apply(g.B_ws_to_world, g.board.object_points())
        uv = project_pinhole(g.K_sub, apply(invert(pose), world))
        return np.round(uv) if quantise else uv

    def sequence(self, poses: np.ndarray, displacements_m: np.ndarray | None = None, *,
                 quantise: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Image points of a whole sequence: main (n, N, 2) and sub (n, M, 2)."""
        n = len(poses)
        d = np.zeros((n, 2)) if displacements_m is None else np.asarray(displacements_m, float)
        main = np.stack([self.main_image_points(P, di, quantise=quantise) for P, di in zip(poses, d, strict=False)])
        sub = np.stack([self.sub_image_points(P, quantise=quantise) for P in poses])
        return main, sub

    def zhang_poses(self, n: int = 15, *, max_tilt_rad: float = 0.5,
                    rng: np.random.Generator | None = None) -> list[np.ndarray]:
        """``n`` poses ``B_WS->CS`` of the board held tilted in front of the sub-camera, wholly in view."""
        rng = rng or np.random.default_rng(11)
        g = self.geometry
        obj = g.board.object_points()
        centre = rigid(np.eye(3), -g.board.centre_ws)
        w, h = g.resolution
        poses: list[np.ndarray] = []
        while len(poses) < n:
            tilt = rng.uniform(-max_tilt_rad, max_tilt_rad, 3) * np.array([1, 1, 0.3])
            dist = g.sub_distance_m * rng.uniform(1.1, 1.6)
            shift = rng.uniform(-0.1, 0.1, 2) * g.sub_fov_m
            B = rigid_from_rotvec(tilt, [shift[0], shift[1], dist]) @ centre
            uv = project_pinhole(g.K_sub, apply(B, obj))
            if np.all((uv > 2) & (uv < [w - 3, h - 3])):
                poses.append(B)
        return poses

    def zhang_views(self, n: int = 15, *, max_tilt_rad: float = 0.5, quantise: bool = False,
                    rng: np.random.Generator | None = None) -> list[np.ndarray]:
        """Image points of the board held at ``n`` tilted poses before installation (for Zhang's method)."""
        obj = self.geometry.board.object_points()
        views = [project_pinhole(self.geometry.K_sub, apply(B, obj))
                 for B in self.zhang_poses(n, max_tilt_rad=max_tilt_rad, rng=rng)]
        return [np.round(v) if quantise else v for v in views]

    def render_board_view(self, B_ws_to_cs: np.ndarray, **kw: Any) -> np.ndarray:
        """Sub-camera image of the board at pose ``B_ws_to_cs`` (e.g. from :meth:`zhang_poses`)."""
        return self.render_sub(self.geometry.B_ws_to_world @ invert(B_ws_to_cs), **kw)

    # ---------------------------------------------------------------- rendered images
    def _rays_to_plane(self, K, B_cam_to_world, B_plane_to_world, u, v):
        """Intersect pixel rays (u, v arrays) with the z=0 plane of a frame; returns plane (x, y)."""
        Kinv = np.linalg.inv(K)
        d_cam = np.stack([u, v, np.ones_like(u)], axis=-1) @ Kinv.T
        to_plane = invert(B_plane_to_world) @ B_cam_to_world
        R, t = to_plane[:3, :3], to_plane[:3, 3]
        d = d_cam @ R.T
        s = -t[2] / d[..., 2]
        return t[0] + s * d[..., 0], t[1] + s * d[..., 1]

    def render_main(self, pose: np.ndarray, displacement_m: ArrayLike = (0.0, 0.0), *, supersample: int = 8,
                    noise: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray:
        """8-bit main-camera image (rows, cols): white circles on black, anti-aliased."""
        g = self.geometry
        w, h = g.resolution
        img = np.full((h, w), 0.08, dtype=np.float32)
        B_cam = pose @ invert(g.B_body_to_main)
        B_plane = g.B_wm_to_world.copy()
        B_plane[:3, 3] += g.B_wm_to_world[:3, :2] @ np.asarray(displacement_m, float)
        centres = self.main_image_points(pose, displacement_m)
        r_px = g.circle_radius_m * g.K_main[0, 0] / g.main_distance_m * 1.05 + 3
        du, dv = _sample_offsets(supersample)
        for (uc, vc), (xc, yc) in zip(centres, g.main_pattern_m, strict=False):
            c0, c1 = int(max(0, np.floor(uc - r_px))), int(min(w, np.ceil(uc + r_px) + 1))
            r0, r1 = int(max(0, np.floor(vc - r_px))), int(min(h, np.ceil(vc + r_px) + 1))
            if c1 <= c0 or r1 <= r0:
                continue
            rr, cc = np.mgrid[r0:r1, c0:c1]
            uu = cc[..., None] + du
            vv = rr[..., None] + dv
            x, y = self._rays_to_plane(g.K_main, B_cam, B_plane, uu, vv)
            inside = ((x - xc) ** 2 + (y - yc) ** 2 <= g.circle_radius_m ** 2).mean(axis=-1)
            img[r0:r1, c0:c1] = 0.08 + (0.9 - 0.08) * inside
        return _to_uint8(img, noise, rng)

    def render_sub(self, pose: np.ndarray, *, supersample: int = 8, noise: float = 0.0,
                   rng: np.random.Generator | None = None) -> np.ndarray:
        """8-bit sub-camera image of the checkerboard (rows, cols), anti-aliased along every edge."""
        g = self.geometry
        w, h = g.resolution
        B_cam = pose  # the sub-camera frame is the rig body
        # Colour at every pixel corner; pixels whose four corners agree need no supersampling.
        v_c, u_c = np.mgrid[-0.5:h:1.0, -0.5:w:1.0]  # type: ignore[misc]  # float slices: pixel corners
        x, y = self._rays_to_plane(g.K_sub, B_cam, g.B_ws_to_world, u_c, v_c)
        col = g.board.colour(x, y)
        a, b, c, d = col[:-1, :-1], col[:-1, 1:], col[1:, :-1], col[1:, 1:]
        img = a.astype(np.float32).copy()
        mixed = np.nonzero((a != b) | (a != c) | (a != d))
        du, dv = _sample_offsets(supersample)
        x, y = self._rays_to_plane(g.K_sub, B_cam, g.B_ws_to_world, mixed[1][:, None] + du, mixed[0][:, None] + dv)
        img[mixed] = g.board.colour(x, y).mean(axis=-1)
        return _to_uint8(img, noise, rng)


def _sample_offsets(n: int) -> tuple[np.ndarray, np.ndarray]:
    """n*n sub-pixel sample offsets on a rotated grid.

    All n*n u and all n*n v positions differ, so the coverage of a near-axis-parallel edge is resolved to 1/n^2 of a pixel, not 1/n.
    """
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    du = (i + (j + 0.5) / n) / n - 0.5
    dv = (j + (i + 0.5) / n) / n - 0.5
    return du.ravel(), dv.ravel()


def _to_uint8(img: np.ndarray, noise: float, rng: np.random.Generator | None, blur_px: float = 0.8) -> np.ndarray:
    """Lens blur (Gaussian point spread of ``blur_px``), sensor noise, 8-bit quantisation."""
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    if noise > 0:
        rng = rng or np.random.default_rng(0)
        img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
    return np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)

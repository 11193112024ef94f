"""The angular steps of a scan, in both angles, from its points.

A terrestrial scanner samples a regular grid of directions: a vertical step between neighbouring points of a
scan line (zenith angle ``theta``) and a horizontal step between lines (azimuth ``phi``). Two estimators:

* :func:`steps_from_neighbours` takes points holding whole angular neighbourhoods (every point of some
  patches of the sky, or consecutive points of a file) and, for each point, its nearest neighbour straight
  above or below (same ``phi``) and its nearest neighbour straight beside it (same ``theta``): the medians of
  those differences are the steps. It needs no particular point order.
* :func:`steps_along_lines` reads the same from the file order of a line scanner: consecutive points of a
  line differ by one step of one angle, consecutive lines by one step of the other.

Both say how regular the grid is (the share of neighbour differences within 10 % of the step). A subsample
of a grid is not a grid at the step (its neighbours lie several steps apart): sample whole neighbourhoods
(:class:`PatchSampler`), never random points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.arrays import unique_sorted
from lidar.angles import spherical32

#: A cloud is a regular scan when at least this share of neighbour differences lies within 10 % of the step.
REGULAR_SHARE = 0.5
#: A neighbour is "straight above" when its azimuth differs by less than this fraction of its zenith difference.
ALIGNED = 0.3
#: Directions this close to the zenith or nadir have no meaningful azimuth step (degrees).
POLE_DEG = 5.0
#: Differences below this are duplicates, not steps (degrees).
TINY_DEG = 1e-7


@dataclass(frozen=True)
class AngularSteps:
    """The two angular steps of a scan and how regular its grid is.

    Attributes
    ----------
    theta_deg, phi_deg : float or None
        Vertical (zenith angle) and horizontal (azimuth) step, degrees; None when not found.
    regular_share : float
        Share of neighbour differences within 10 % of the step (the lower of the two angles).
    points : int
        Points the estimate used.
    method : str
        How the neighbours were found.
    """

    theta_deg: float | None
    phi_deg: float | None
    regular_share: float
    points: int
    method: str

    @property
    def regular(self) -> bool:
        return self.theta_deg is not None and self.phi_deg is not None and self.regular_share >= REGULAR_SHARE

    @property
    def step_deg(self) -> float | None:
        """The coarser of the two steps (what decides whether a small target gets points), or None."""
        if not self.regular:
            return None
        return max(self.theta_deg or 0.0, self.phi_deg or 0.0)


def angles_deg(xyz: np.ndarray, dtype: type = np.float64) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) in degrees of points in the scanner frame; phi in [0, 360). ``dtype`` float32 is cheaper."""
    turn: np.ndarray = np.asarray(360.0, dtype=dtype)
    if np.dtype(dtype) == np.float32:  # four times quicker, within 3e-5 degrees; on copies (it overwrites)
        theta, phi, _ = spherical32(*(xyz[:, k].astype(np.float32) for k in range(3)))
        phi[phi >= turn] -= turn
        return theta, phi
    x: np.ndarray = np.asarray(xyz[:, 0], dtype=dtype)
    y: np.ndarray = np.asarray(xyz[:, 1], dtype=dtype)
    z: np.ndarray = np.asarray(xyz[:, 2], dtype=dtype)
    deg: np.ndarray = np.asarray(180.0 / np.pi, dtype=dtype)
    theta = np.arctan2(np.hypot(x, y), z)
    theta *= deg
    phi = np.arctan2(y, x)
    phi *= deg
    phi[phi < 0] += turn
    phi[phi >= turn] -= turn
    return theta, phi


def _median_share(values: np.ndarray) -> tuple[float | None, float]:
    values = values[values > TINY_DEG]
    if values.size < 10:
        return None, 0.0
    med = float(np.median(values))
    return med, float(np.mean(np.abs(values - med) <= 0.1 * med))


def _away_from_poles(theta: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ok = (theta > POLE_DEG) & (theta < 180.0 - POLE_DEG)
    return theta[ok], phi[ok]


def steps_from_neighbours(theta_deg: np.ndarray, phi_deg: np.ndarray, *, method: str = "angular neighbours"
                          ) -> AngularSteps:
    """Both steps from each point's nearest neighbour straight above/below and straight beside it.

    Parameters
    ----------
    theta_deg, phi_deg : (N,) arrays, degrees
        Directions holding whole angular neighbourhoods (no subsampling inside them). Azimuths may be
        unwrapped (e.g. -1..1 across the seam); within one call they are taken as given.
    method : str, keyword-only
        Recorded on the result.

    Returns
    -------
    AngularSteps

    Notes
    -----
    The eight nearest neighbours in the (theta, phi) plane are classified as straight above/below or straight
    beside a point. When one step is more than about three times the other, no neighbour of that kind is
    among the eight: that angle's axis is then compressed by four and the search repeated (up to four times),
    so steps as different as 0.001 x 0.06 degrees are found.
    """
    # local: scipy.spatial costs 'info' and the other file commands 0.3-0.4 s of start-up (measured)
    from scipy.spatial import cKDTree

    theta, phi = _away_from_poles(np.asarray(theta_deg, np.float64), np.asarray(phi_deg, np.float64))
    n = theta.size
    if n < 20:
        return AngularSteps(None, None, 0.0, int(n), method)
    scale = np.array([1.0, 1.0])
    found: list[np.ndarray | None] = [None, None]
    for _ in range(5):
        pts = np.column_stack([(theta - theta.min()) * scale[0], (phi - phi.min()) * scale[1]])
        _, idx = cKDTree(pts).query(pts, k=min(9, n), workers=-1)
        d = np.abs(pts[idx[:, 1:]] - pts[:, None, :]) / scale  # (n, 8, 2) in degrees
        dt, dp = d[..., 0], d[..., 1]
        kinds = ((dp < ALIGNED * dt) & (dt > TINY_DEG), (dt < ALIGNED * dp) & (dp > TINY_DEG))
        share = []
        for k, kind in enumerate(kinds):
            has = kind.any(axis=1)
            share.append(float(has.mean()))
            if has.mean() >= 0.5:
                first = np.argmax(kind[has], axis=1)
                found[k] = (dt if k == 0 else dp)[has][np.arange(int(has.sum())), first]
        if found[0] is not None and found[1] is not None:
            break
        # the missing kind's neighbours lie beyond the eight nearest: bring that axis closer
        for k in (0, 1):
            if found[k] is None:
                scale[k] /= 4.0
    (t_step, t_share), (p_step, p_share) = (_median_share(f) if f is not None else (None, 0.0) for f in found)
    return AngularSteps(t_step, p_step, min(t_share, p_share), int(n), method)


def steps_along_lines(theta_deg: np.ndarray, phi_deg: np.ndarray) -> AngularSteps:
    """Both steps from the file order of a line scanner (column by column or row by row).

    Consecutive points of a line differ in one angle by one step (a few by several, where returns are
    missing); the lines themselves, each at one value of the other angle, differ by the other step.

    Parameters
    ----------
    theta_deg, phi_deg : (N,) arrays, degrees, in file order

    Returns
    -------
    AngularSteps (``regular_share`` near 0 for files not in scan order)
    """
    theta = np.asarray(theta_deg, np.float64)
    phi = np.asarray(phi_deg, np.float64)
    if theta.size < 20:
        return AngularSteps(None, None, 0.0, int(theta.size), "scan lines")
    dt = np.abs(np.diff(theta))
    dp = np.abs((np.diff(phi) + 180.0) % 360.0 - 180.0)
    vertical = (dp < ALIGNED * dt) & (dt > TINY_DEG)
    horizontal = (dt < ALIGNED * dp) & (dp > TINY_DEG)
    column_major = vertical.sum() >= horizontal.sum()
    across = phi if column_major else theta
    d_in, d_across = (dt, dp) if column_major else (dp, dt)
    step_in, _ = _median_share(d_in[vertical if column_major else horizontal])
    if step_in is None:
        return AngularSteps(None, None, 0.0, int(theta.size), "scan lines")
    # in a line: one step of one angle (up to three where returns are missing), none of the other
    in_line = (d_across < ALIGNED * step_in) & (d_in > TINY_DEG) & (d_in < 3.5 * step_in)
    step_in, share_in = _median_share(d_in[in_line])
    if step_in is None:
        return AngularSteps(None, None, 0.0, int(theta.size), "scan lines")
    # lines: runs of in-line moves; each line sits at one value of the other angle
    breaks = np.flatnonzero(~in_line & ~((dt <= TINY_DEG) & (dp <= TINY_DEG))) + 1
    starts = np.concatenate([[0], breaks])
    ends = np.concatenate([breaks, [theta.size]])
    long_enough = (ends - starts) >= 3
    level = np.array([np.median(across[s:e]) for s, e in zip(starts[long_enough], ends[long_enough], strict=False)])
    if level.size < 3:
        return AngularSteps(None, None, 0.0, int(theta.size), "scan lines")
    jumps = np.abs((np.diff(level) + 180.0) % 360.0 - 180.0) if column_major else np.abs(np.diff(level))
    step_across, share_across = _median_share(jumps)
    t_step, p_step = (step_in, step_across) if column_major else (step_across, step_in)
    return AngularSteps(t_step, p_step, min(share_in, share_across), int(theta.size), "scan lines")


class PatchSampler:
    """Every point of a few angular patches of a scan, fed chunk by chunk, within a point budget.

    The sky is cut into ``cell_deg`` cells; each cell gets a pseudo-random rank from its indices, and the
    sampler keeps every point of the lowest-ranked cells that fit ``budget`` points. Whole cells keep whole
    neighbourhoods (what :func:`steps_from_neighbours` needs); the ranks make the choice independent of the
    file's order and spread it over the scan. Memory: about ``budget`` points.

    Parameters
    ----------
    budget : int
        Points kept at most (default 200,000).
    cell_deg : float
        Patch size (default 2 degrees: 200 x 200 points of a 0.01-degree scan, 10 x 10 of a 0.2-degree one).
    """

    def __init__(self, budget: int = 200_000, cell_deg: float = 2.0):
        self.budget = int(budget)
        self.cell_deg = float(cell_deg)
        self.limit = 1.0
        self._theta: list[np.ndarray] = []
        self._phi: list[np.ndarray] = []
        self._rank: list[np.ndarray] = []
        self._kept = 0
        self._table: np.ndarray | None = None

    def _ranks(self, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """Each direction's cell rank, looked up in a table of every cell's rank (a few thousand cells)."""
        rows, cols = int(np.ceil(180.0 / self.cell_deg)) + 1, int(np.ceil(360.0 / self.cell_deg)) + 1
        if self._table is None:
            r = np.repeat(np.arange(rows, dtype=np.uint64), cols)
            c = np.tile(np.arange(cols, dtype=np.uint64), rows)
            h = (r * np.uint64(0x9E3779B97F4A7C15) + c * np.uint64(0xC2B2AE3D27D4EB4F)) & np.uint64((1 << 61) - 1)
            h ^= h >> np.uint64(29)
            h = (h * np.uint64(0xBF58476D1CE4E5B9)) & np.uint64((1 << 61) - 1)
            self._table = (h >> np.uint64(8)).astype(np.float64) / float(1 << 53)
        inv = 1.0 / self.cell_deg
        row = np.clip((theta * inv).astype(np.int32), 0, rows - 1)
        col = np.clip((phi * inv).astype(np.int32), 0, cols - 1)
        row *= cols
        row += col
        return self._table[row]

    def wanted(self, theta_deg: np.ndarray, phi_deg: np.ndarray) -> np.ndarray:
        """(N,) bool: which of these directions fall in cells the sampler keeps (float32 angles will do)."""
        return self._ranks(np.asarray(theta_deg), np.asarray(phi_deg)) < self.limit

    def add(self, theta_deg: np.ndarray, phi_deg: np.ndarray) -> None:
        """Offer a chunk of directions (degrees)."""
        theta = np.asarray(theta_deg, np.float64)
        phi = np.asarray(phi_deg, np.float64)
        rank = self._ranks(theta, phi)
        keep = rank < self.limit
        if not keep.any():
            return
        self._theta.append(theta[keep])
        self._phi.append(phi[keep])
        self._rank.append(rank[keep])
        self._kept += int(keep.sum())
        if self._kept > self.budget:
            self._shrink()

    def _shrink(self) -> None:
        rank = np.concatenate(self._rank)
        values, counts = np.unique(rank, return_counts=True)
        total = np.cumsum(counts)
        cut = max(int(np.searchsorted(total, 0.75 * self.budget, side="right")), 1)
        if cut < len(values):
            self.limit = float(values[cut])  # keep the cells ranked below this one
        keep = rank < self.limit
        self._theta = [np.concatenate(self._theta)[keep]]
        self._phi = [np.concatenate(self._phi)[keep]]
        self._rank = [rank[keep]]
        self._kept = int(keep.sum())

    def steps(self) -> AngularSteps:
        """The steps from the points kept so far."""
        if not self._theta:
            return AngularSteps(None, None, 0.0, 0, "angular neighbours")
        theta, phi = np.concatenate(self._theta), np.concatenate(self._phi)
        return steps_from_neighbours(theta, phi, method=f"angular neighbours in {len(unique_sorted(np.concatenate(self._rank)))} "
                                                        f"patches of {self.cell_deg:g} deg")

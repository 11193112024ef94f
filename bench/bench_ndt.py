"""PCL's NDT (pcl_ndt3d) against our point-to-plane ICP on the same stable parts (issue 13).

A synthetic scene of ground, pier blocks and an abutment wall with 3 mm noise in
project coordinates; the source is moved by a known 0.05 deg / 2.7 cm motion.
Pose error at three points where the bridge is (pier faces, wall), and time,
for our ICP (the baseline) and NDT. Usage: ``./run bench bench_ndt [N]`` (``--small``: 30,000 points).
"""
from __future__ import annotations

import time

import numpy as np
from _harness import figures, small_mode
from scipy.spatial.transform import Rotation

from registration.icp import refine_icp
from registration.ndt import ndt_available, refine_ndt
from registration.transform import Transform

OFFSET = np.array([4.5e5, 5.4e6, 100.0])


def scene(rng, n):
    k = rng.integers(0, 4, n)
    p = np.column_stack([rng.uniform(-5, 45, n), rng.uniform(-8, 8, n), np.zeros(n)])
    p[k == 1, 0] = rng.uniform(0, 2, (k == 1).sum()); p[k == 1, 2] = rng.uniform(0, 7, (k == 1).sum())
    p[k == 2, 0] = 39.0; p[k == 2, 2] = rng.uniform(0, 7, (k == 2).sum())
    p[k == 3, 1] = -2.5 + 0.3 * np.sin(p[k == 3, 0]); p[k == 3, 2] = rng.uniform(0, 7, (k == 3).sum())
    return p + rng.normal(0, 0.003, p.shape) + OFFSET


def main(n: int) -> None:
    if not ndt_available():
        print("pcl_ndt3d is not installed (Debian pcl-tools); ./run setup installs it as root; its row is skipped")
        rows = [("ICP (baseline)", refine_icp)]
    else:
        rows = [("ICP (baseline)", refine_icp), ("PCL NDT (pcl_ndt3d)", refine_ndt)]
    rng = np.random.default_rng(1)
    tgt = scene(rng, n)
    centre = tgt.mean(axis=0)
    rot = Rotation.from_euler("z", 0.05, degrees=True).as_matrix()
    move = np.array([0.02, -0.015, 0.01])
    src = (scene(rng, n) - centre - move) @ rot + centre
    checks = np.array([[1.0, 0, 5], [39, 0, 5], [20, -2.5, 3]]) + OFFSET
    before = (checks - centre - move) @ rot + centre
    print(f"{n:,} points per epoch; start error {np.abs(before - checks).max() * 1000:.1f} mm at the check points")
    done = []
    for name, fn in rows:
        t0 = time.perf_counter()
        res = fn(src, tgt, Transform.identity(), offset=centre)
        dt = time.perf_counter() - t0
        err = np.abs(res.transform.apply(before) - checks).max() * 1000
        done.append((name, err, dt))
    base = done[0][2]
    print(f"{'refinement':24s} {'max error at checks':>20s} {'time':>8s} {'time ratio':>10s}")
    for name, err, dt in done:
        print(f"{name:24s} {err:17.2f} mm {dt:7.1f} s {dt / base:9.2f}x")
    ndt = done[1] if len(done) > 1 else None
    figures(points=n, start_error_mm=float(np.abs(before - checks).max() * 1000), icp_error_mm=done[0][1],
            ndt_error_mm=ndt[1] if ndt else None, ndt_time_ratio=ndt[2] / base if ndt else None)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 30_000 if _small else 1_000_000)

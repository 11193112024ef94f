"""ICP and M3C2 through BridgeSurvey's wrappers against Open3D's and py4dgeo's own plain calls (issue 5).

Same clouds, same parameters, each in a fresh process; the wrapper overhead target is <= 10 %.
Clouds: a synthetic scene of ground and pier faces with 3 mm noise, 1 M and 10 M points.
Usage: ``./run bench bench_registration [SIZES...]`` (default 1000000 10000000; ``--small``: 30000, one process
each).
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[0]))

from _harness import figures, measure, row, small_mode  # noqa: E402

SCENE = """
import numpy as np
from scipy.spatial.transform import Rotation
rng = np.random.default_rng(1)
n = {n}
def scene():
    k = rng.integers(0, 4, n)
    p = np.column_stack([rng.uniform(-5, 45, n), rng.uniform(-8, 8, n), np.zeros(n)])
    p[k == 1, 0] = 1.0; p[k == 1, 2] = rng.uniform(0, 7, (k == 1).sum())
    p[k == 2, 0] = 39.0; p[k == 2, 2] = rng.uniform(0, 7, (k == 2).sum())
    p[k == 3, 1] = -2.5; p[k == 3, 2] = rng.uniform(0, 7, (k == 3).sum())
    return p + rng.normal(0, 0.003, p.shape) + np.array([4.5e5, 5.4e6, 100.0])
tgt = scene()
R = Rotation.from_euler("z", 0.05, degrees=True).as_matrix()
src = (scene() - tgt.mean(0)) @ R.T + tgt.mean(0) + 0.01
"""

OURS_ICP = """
from registration.icp import refine_icp
from registration.transform import Transform
res = refine_icp(src, tgt, Transform.identity(), voxels_m=(0.2, 0.08, 0.04))
"""

PLAIN_ICP = """
import open3d as o3d
reg = o3d.pipelines.registration
off = tgt.mean(0)
sc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(src - off))
tc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(tgt - off))
T = np.eye(4)
for v in (0.2, 0.08, 0.04):
    s = sc.voxel_down_sample(v); t = tc.voxel_down_sample(v)
    t.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=3 * v, max_nn=30))
    T = reg.registration_icp(s, t, 2.5 * v, T, reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=v)),
                             reg.ICPConvergenceCriteria(max_iteration=30)).transformation
"""

CORE = """
from registration.change import core_points_grid
core = core_points_grid(tgt, 0.25)
"""

OURS_M3C2 = """
from registration.change import m3c2
res = m3c2(tgt, src, core, normal_radii=(0.5,), cyl_radius=0.25, max_distance=0.5)
"""

PLAIN_M3C2 = """
import logging, py4dgeo
logging.getLogger("py4dgeo").setLevel(logging.WARNING)
off = tgt.mean(0)
e1 = py4dgeo.Epoch(tgt - off); e2 = py4dgeo.Epoch(src - off)
d, u = py4dgeo.M3C2(epochs=(e1, e2), corepoints=core - off, normal_radii=(0.5,), cyl_radius=0.25,
                    max_distance=0.5, registration_error=0.0, orientation_vector=np.array([0., 0., 1.])).run()
"""


def main(sizes=(1_000_000, 10_000_000), *, repeat: int = 2) -> None:
    found = {}
    for n in sizes:
        setup = SCENE.format(n=n)
        b_icp = measure(setup, PLAIN_ICP, repeat=repeat)
        o_icp = measure(setup, OURS_ICP, repeat=repeat)
        print(row(f"Open3D ICP, plain calls, {n / 1e6:g} M", b_icp))
        print(row(f"refine_icp, {n / 1e6:g} M", o_icp, b_icp), flush=True)
        b_m3c2 = measure(setup + CORE, PLAIN_M3C2, repeat=repeat)
        o_m3c2 = measure(setup + CORE, OURS_M3C2, repeat=repeat)
        print(row(f"py4dgeo M3C2, plain, {n / 1e6:g} M", b_m3c2))
        print(row(f"registration.m3c2, {n / 1e6:g} M", o_m3c2, b_m3c2))
        print(f"RESULT {n / 1e6:g} M points: wrapper overhead ICP {o_icp['seconds'] / b_icp['seconds'] - 1:+.1%}, "
              f"M3C2 {o_m3c2['seconds'] / b_m3c2['seconds'] - 1:+.1%} (target <= +10 %)", flush=True)
        found[f"icp_ratio_{n}"] = o_icp["seconds"] / b_icp["seconds"]
        found[f"m3c2_ratio_{n}"] = o_m3c2["seconds"] / b_m3c2["seconds"]
    figures(**found)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(tuple(int(a) for a in _args) or ((30_000,) if _small else (1_000_000, 10_000_000)), repeat=1 if _small else 2)

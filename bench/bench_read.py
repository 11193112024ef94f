"""LAS/LAZ read throughput and memory: our reader against laspy's plain read of the same file.

Targets (issue 2): throughput >= 0.9x laspy's, peak memory <= 1.5x the decoded arrays,
on a 20 M point file. Usage: ``./run bench bench_read [N_POINTS]`` (``--small``: 300,000 points, one process
each).
"""
from __future__ import annotations

import numpy as np
from _harness import OUT, figures, measure, row, small_mode


def make_file(path, n):
    import laspy

    if path.exists():
        return
    rng = np.random.default_rng(0)
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = np.array([1e-4] * 3)
    header.offsets = np.array([0.0, 0.0, 0.0])
    las = laspy.LasData(header)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    xyz = d * rng.uniform(2, 60, n)[:, None]
    las.x, las.y, las.z = xyz.T
    las.intensity = rng.integers(0, 65535, n).astype(np.uint16)
    las.write(path, do_compress=path.suffix == ".laz")


def main(n: int = 20_000_000, *, repeat: int = 3) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    print(f"{n:,} points, point format 1 (28 bytes/point); best of {repeat} fresh processes")
    found = {}
    for suffix in (".las", ".laz"):
        path = OUT / f"read_{n}{suffix}"
        make_file(path, n)
        base = measure("import laspy", f"las = laspy.read({str(path)!r})", repeat=repeat)
        base_xyz = measure("import laspy, numpy as np",
                           f"las = laspy.read({str(path)!r}); xyz = np.column_stack([las.x, las.y, las.z])",
                           repeat=repeat)
        ours = measure("from lidar.io.las import read_las", f"scan = read_las({str(path)!r})\n"
                       f"assert len(scan.xyz_socs) == {n}", repeat=repeat)
        decoded_mb = n * 28 / 2**20
        ours_out_mb = n * (24 + 4 + 2) / 2**20
        print(row(f"laspy.read {suffix}", base))
        print(row(f"laspy.read + float64 xyz {suffix}", base_xyz, base))
        print(row(f"BridgeSurvey read_las {suffix} (xyz+intensity)", ours, base))
        print(f"  decoded point records {decoded_mb:.0f} MiB; our output arrays {ours_out_mb:.0f} MiB; "
              f"our peak / decoded records x{ours['peak_mb'] / decoded_mb:.2f}; "
              f"our peak / our output arrays x{ours['peak_mb'] / ours_out_mb:.2f}")
        print(f"  RESULT {suffix}: throughput vs laspy x{base['seconds'] / ours['seconds']:.2f} (target >= 0.90)")
        found[f"throughput_ratio_{suffix[1:]}"] = base["seconds"] / ours["seconds"]
        found[f"peak_ratio_{suffix[1:]}"] = ours["peak_mb"] / decoded_mb
    figures(points=n, **found)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 300_000 if _small else 20_000_000, repeat=1 if _small else 3)

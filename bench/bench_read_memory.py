"""Peak memory of reading each format, as a ratio of the decoded arrays (issue 13).

Each read runs in a fresh process; its peak RSS above the process's baseline
(after imports) is divided by the size of what it returns (xyz float64,
intensity float32, raw intensity). Target: about 2x plus a constant.
Usage: ``./run bench bench_read_memory [N]`` (default 2,000,000 points; ``--small``: 100,000).
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _harness import figures, small_mode

CHILD = """
import resource, sys
import numpy as np
from lidar.io import read_scans
import lidar.io.ply, plyfile, pandas, laspy, pye57, lzf
import os
base = int(open("/proc/self/statm").read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024  # current RSS, KiB
scans = read_scans(sys.argv[1])
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
decoded = sum(s.xyz_socs.nbytes + s.intensity.nbytes + s.intensity_raw.nbytes for s in scans)
print((peak - base) * 1024, decoded)
"""


def main(n: int) -> None:
    from lidar.io import write_scan
    from lidar.scan import Scan, normalise_intensity

    rng = np.random.default_rng(0)
    raw = rng.integers(0, 65535, n).astype(np.uint16)
    scan = Scan(xyz_socs=rng.uniform(-50, 50, (n, 3)), intensity=normalise_intensity(raw), intensity_raw=raw)
    print(f"{n:,} points; peak memory above the baseline / decoded arrays")
    found = {}
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in (".las", ".laz", ".e57", ".ply", ".pcd", ".ptx", ".pts", ".xyz"):
            path = write_scan(scan, Path(tmp) / f"s{suffix}")
            out = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, check=True)
            peak, decoded = (int(v) for v in out.stdout.split())
            print(f"{suffix:5s} file {path.stat().st_size / 2**20:7.1f} MiB  decoded {decoded / 2**20:6.1f} MiB  "
                  f"peak {peak / 2**20:7.1f} MiB  ratio {peak / decoded:4.2f}x")
            found[f"peak_mb_{suffix[1:]}"] = peak / 2**20
            found[f"decoded_mb_{suffix[1:]}"] = decoded / 2**20
    figures(points=n, **found)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 100_000 if _small else 2_000_000)

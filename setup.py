"""The package's one compiled part: the coarse map's inner loops (lidar/native/coarse_map.c).

Every coarse map goes through them (the campaign's and plan-file's): the install needs a C compiler. The
library carries the digest of the source it was built from; lidar.native refuses a library built from another
version of the source. The metadata and dependencies are in setup.cfg.
"""
import hashlib
from pathlib import Path

from setuptools import Extension, setup

SOURCE = "lidar/native/coarse_map.c"
DIGEST = hashlib.sha256((Path(__file__).resolve().parent / SOURCE).read_bytes()).hexdigest()

setup(ext_modules=[Extension(
    "lidar.native._coarse_map", sources=[SOURCE],
    define_macros=[("BS_SOURCE_DIGEST", f'"{DIGEST[:16]}"')],
    # no fused multiply-adds: numpy rounds a product and a sum apart, and the library must give its results;
    # no trapping math: the loops' comparisons become vector selects (the same values, no floating-point traps)
    extra_compile_args=["-O3", "-ffp-contract=off", "-fno-math-errno", "-fno-trapping-math"],
)])

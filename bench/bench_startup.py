"""Start-up of the command line (issue 27): ``bridgesurvey --help`` and a refused command, against ``python -c pass``.

Every measurement is a fresh process, as a user starts it; the best of N runs (default 15) after one warm-up
run that writes the byte-code caches (``PYTHONDONTWRITEBYTECODE`` is removed for the runs: a user's
interpreter keeps its ``.pyc`` files, and compiling the sources every time is not start-up). The ratios are
against ``python -c pass`` measured in the same run, on the same interpreter. Target: both ≤ 0.3 s.
Usage: ``./run bench bench_startup [RUNS]`` (``--small``: 2 runs; the figures are printed, the exit status does not
hold them to the target: a busy test machine is not a user's).
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _harness import figures, small_mode

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 0.3


def best_of(argv: list[str], runs: int, env: dict, expect: int) -> float:
    """Best wall-clock seconds of ``argv`` over ``runs`` fresh processes (after one warm-up run)."""
    times = []
    for k in range(runs + 1):
        t0 = time.perf_counter()
        res = subprocess.run(argv, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        dt = time.perf_counter() - t0
        if res.returncode != expect:
            raise RuntimeError(f"{' '.join(argv)} exited {res.returncode}, expected {expect}: {res.stderr[-500:]}")
        if k:
            times.append(dt)
    return min(times)


def main() -> int:
    small, args = small_mode()
    runs = int(args[0]) if args else 2 if small else 15
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    script = Path(sys.executable).with_name("bridgesurvey")  # the installed command, as a user runs it
    cli = [str(script)] if script.exists() else [sys.executable, "-m", "app.cli.main"]
    with tempfile.TemporaryDirectory() as tmp:
        refused = cli + ["plan", tmp, "--epoch", "2026-03-02", "--out", str(Path(tmp) / "nope" / "plan.json")]
        base = best_of([sys.executable, "-c", "pass"], runs, env, 0)
        rows = [("python -c pass", base),
                ("bridgesurvey --help", best_of(cli + ["--help"], runs, env, 0)),
                ("bridgesurvey plan ... --out nope/plan.json (refused)", best_of(refused, runs, env, 1))]
    print(f"start-up, best of {runs} fresh processes ({os.cpu_count()} cores, load {os.getloadavg()[0]:.1f})")
    ok = True
    for name, seconds in rows:
        extra = "" if name.startswith("python") else \
            f"   x{seconds / base:5.1f} python -c pass, +{seconds - base:.3f} s" + \
            ("" if seconds <= TARGET_S else f"   ABOVE the {TARGET_S} s target")
        ok &= name.startswith("python") or seconds <= TARGET_S
        print(f"  {name:<55s} {seconds:6.3f} s{extra}")
    figures(python_s=rows[0][1], help_s=rows[1][1], refused_s=rows[2][1])
    return 0 if ok or small else 1


if __name__ == "__main__":
    sys.exit(main())

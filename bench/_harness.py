"""Tiny benchmark harness: run code in a fresh subprocess, report its best time and peak memory.

Each measurement runs in its own interpreter so the peak resident memory is
that of the measured work alone (measured above the memory after set-up).
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"

_CHILD = """
import json, time, gc
def _status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1])
{setup}
gc.collect()
open("/proc/self/clear_refs", "w").write("5")  # reset the peak (VmHWM) to the current RSS
rss0 = _status("VmRSS")
t0 = time.perf_counter()
{body}
dt = time.perf_counter() - t0
print("@@" + json.dumps({{"seconds": dt, "peak_mb": (_status("VmHWM") - rss0) / 1024.0}}))
"""


def measure(setup: str, body: str, *, repeat: int = 3) -> dict:
    """Best seconds and the peak extra memory (MiB) of ``body`` over ``repeat`` fresh runs."""
    code = _CHILD.format(setup=textwrap.dedent(setup), body=textwrap.dedent(body))
    best = None
    for _ in range(repeat):
        res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
        if res.returncode != 0:
            raise RuntimeError(res.stderr[-2000:])
        line = next(ln for ln in res.stdout.splitlines() if ln.startswith("@@"))
        r = json.loads(line[2:])
        if best is None or r["seconds"] < best["seconds"]:
            best = {**r, "peak_mb": max(r["peak_mb"], best["peak_mb"]) if best else r["peak_mb"]}
    return best


def row(name: str, r: dict, base: dict | None = None) -> str:
    text = f"{name:<46s} {r['seconds']:8.3f} s  {r['peak_mb']:8.1f} MiB"
    if base is not None:
        text += f"   time x{r['seconds'] / base['seconds']:.2f}  throughput x{base['seconds'] / r['seconds']:.2f}"
    return text

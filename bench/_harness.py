"""Tiny benchmark harness: run code in a fresh subprocess, report its best time and peak memory.

Each measurement runs in its own interpreter so the peak resident memory is
that of the measured work alone (measured above the memory after set-up).
"""
from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"
#: Where a bench writes the table the documentation shows (docs/figures/NAME.md, included by the pages).
FIGURES = ROOT / "docs" / "figures"

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


def machine() -> str:
    """One line naming the machine a bench ran on: system, processor, cores, memory, Python and numpy."""
    cpu = platform.processor() or platform.machine()
    memory = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                memory = f", {int(line.split()[1]) / 1024 ** 2:.0f} GiB"
                break
    except OSError:  # not Linux: the platform module's words only
        pass
    return (f"{platform.system()} {platform.release()} {platform.machine()}, {cpu}, {os.cpu_count()} cores{memory}, "
            f"Python {platform.python_version()}, numpy {numpy.__version__}")


def write_figure(name: str, table: str, *, notes: str = "", argv: list[str] | None = None) -> Path:
    """Write a bench's Markdown table to ``docs/figures/NAME.md``, where the documentation's pages include it.

    The file starts with the date, the command that wrote it (``./run bench NAME`` and the bench's own
    arguments) and the machine line, so a figure in the documentation always says where it came from.

    Parameters
    ----------
    name : str
        The file's stem, by convention the bench's own (``bench/NAME.py``).
    table : str
        The table in Markdown (a header line, the ``|---|`` line, the rows).
    notes : str
        Lines printed under the table (footnotes, the run's conclusions), Markdown.
    argv : list of str, optional
        The bench's arguments, recorded in the command; by default ``sys.argv[1:]``.
    """
    args = sys.argv[1:] if argv is None else argv
    if SMALL in args:  # a small run's table is no figure for the documentation
        print(f"small mode: {FIGURES / f'{name}.md'} left as it was")
        return FIGURES / f"{name}.md"
    command = " ".join(["./run bench", name, *args])
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    text = (f"<!-- Written by {command} (bench/_harness.py write_figure): run the bench again rather than "
            f"editing this file. -->\n"
            f"*Measured {when} by `{command}` on {machine()}.*\n\n{table.strip()}\n")
    if notes.strip():
        text += f"\n{notes.strip()}\n"
    FIGURES.mkdir(parents=True, exist_ok=True)
    path = FIGURES / f"{name}.md"
    path.write_text(text, encoding="utf-8")
    print(f"table written to {path}")
    return path


#: A bench given this flag runs its small mode: the same code path on a smaller scene, fewer repetitions or smaller
#: files, in seconds (``tests/test_benches.py`` runs every bench so inside ``./run test``).
SMALL = "--small"
#: The line a bench prints its key figures on (JSON after the prefix): what the small-mode test checks.
FIGURES_LINE = "BENCH-FIGURES "


def small_mode(argv: list[str] | None = None) -> tuple[bool, list[str]]:
    """Whether ``--small`` is among the arguments (default ``sys.argv[1:]``), and the other arguments."""
    args = list(sys.argv[1:] if argv is None else argv)
    return SMALL in args, [a for a in args if a != SMALL]


def figures(**values: float | int | None) -> None:
    """Print the bench's key figures as one line of JSON (read by the small-mode test; NaN printed as null)."""
    clean = {k: (None if v is None or (isinstance(v, float) and v != v) else v) for k, v in values.items()}
    print(FIGURES_LINE + json.dumps(clean), flush=True)

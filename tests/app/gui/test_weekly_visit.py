"""The weekly visit through the application (``visit_xcb.py``), in its own process on the X display.

Qt's platform is fixed per process and the other GUI tests use the offscreen one; the visit needs a
real OpenGL window for its 3-D tab. ``./run test`` provides the display with Xvfb.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.gui, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[3]


def test_a_weekly_visit_on_a_1366x768_screen(tmp_path):
    if not os.environ.get("DISPLAY"):
        pytest.skip("no X display (./run test provides one with Xvfb)")
    env = {**os.environ, "QT_QPA_PLATFORM": "xcb", "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "0", "-s", "-p", "no:cacheprovider",
                          "--basetemp", str(tmp_path / "visit"), str(ROOT / "tests" / "app" / "gui" / "visit_xcb.py")],
                         env=env, cwd=ROOT, capture_output=True, text=True, timeout=1500)
    assert res.returncode == 0 and "1 passed" in res.stdout, res.stdout[-6000:] + _crash(res.stderr)
    print(next((line for line in res.stdout.splitlines() if line.startswith("TICKS")), "no TICKS line"))


def _crash(stderr: str) -> str:
    """The crashed thread's stack that faulthandler wrote (it ends with a long list of modules), or the tail."""
    i = stderr.find("Fatal Python error")
    return stderr[i:i + 5000] if i >= 0 else stderr[-3000:]

"""The 3-D view under Xvfb: a real OpenGL window, level of detail, markers, picking, change colours.

Qt's platform is fixed per process and the other GUI tests use the offscreen one, so this test
runs the 3-D view in its own process on the X display ``./run test`` provides.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.gui

SCRIPT = textwrap.dedent("""
    import faulthandler
    import sys
    import time
    import numpy as np
    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication
    from app.gui.main_window import MainWindow

    faulthandler.dump_traceback_later(400, exit=True)  # a hang shows where it is instead of timing out
    QSettings.setPath(QSettings.IniFormat, QSettings.UserScope, sys.argv[2])
    app = QApplication([])
    win = MainWindow()
    win.resize(1200, 800)
    win.show()
    assert win.open_campaign(sys.argv[1])

    def wait():
        while win.jobs.busy:  # sleep (it releases the GIL) and let the finished signals arrive
            time.sleep(0.02)
            app.processEvents()
        for _ in range(20):
            app.processEvents()

    win.state.select(epoch="2026-03-16")
    win.tabs.setCurrentWidget(win.cloud_view)
    assert win.cloud_view.show_btn.isEnabled()
    win.cloud_view.cloud = None
    win.commands.show_cloud("intensity")
    wait()
    cv = win.cloud_view
    assert cv.cloud is not None and cv.cloud.value_name == "intensity"
    assert len(cv.cloud.xyz) <= 1_500_000 and set(cv.cloud.marker_ids) >= {"R1", "M3"}
    img = cv.plotter.screenshot(None, return_img=True)
    assert img.std() > 5, "the 3-D view drew nothing"
    cv.pick_target("M3")
    assert win.state.selection.reflector == "M3" and cv.selected == "M3"
    assert win.displacements.target.currentText() == "M3"
    win.commands.show_cloud("change")
    wait()
    assert cv.cloud.value_name.startswith("M3C2 change") and np.isfinite(cv.cloud.values).mean() > 0.5
    assert cv.scale.source == "the deck and piers" and cv.mode.currentData() == "change"
    assert cv.plotter.render_timer.isActive() is False  # renders on demand only
    deck = np.abs(cv.cloud.values[np.isfinite(cv.cloud.values)])
    print("OK", len(cv.cloud.xyz), float(np.median(deck)))
    win.close()
""")


@pytest.mark.slow
def test_3d_view_in_an_x_window(processed_copy, tmp_path):
    if not os.environ.get("DISPLAY"):
        pytest.skip("no X display (./run test provides one with Xvfb)")
    env = {**os.environ, "QT_QPA_PLATFORM": "xcb", "MPLBACKEND": "Agg"}
    res = subprocess.run([sys.executable, "-c", SCRIPT, str(processed_copy), str(tmp_path / "settings")], env=env,
                         cwd=Path(__file__).resolve().parents[3], capture_output=True, text=True, timeout=500)
    assert res.returncode == 0 and "OK" in res.stdout, res.stdout[-3000:] + res.stderr[-3000:]

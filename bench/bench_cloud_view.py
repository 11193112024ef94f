"""3-D view: frame time of a large cloud with the view's level of detail, against plain pyvista drawing.

Baseline, measured in the same run: ``QtInteractor.add_points`` of the same cloud, every point every
frame. Ours: the view's decimation for display (at most 1.5 M points) and its interactive level of
detail (at most 150 k points while the view moves). Needs an X display; without one it re-runs
itself under Xvfb. On Xvfb, OpenGL is software-rendered: real graphics cards are far faster, the
ratios are what carry over. Usage: ``./run bench bench_cloud_view [N_POINTS]`` (``--small``: 50,000 points).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import numpy as np
from _harness import figures, small_mode


def frame_ms(plotter, frames: int = 5) -> float:
    t = time.perf_counter()
    for k in range(frames):
        plotter.camera.azimuth = 5.0 * (k + 1)
        plotter.render()
    return (time.perf_counter() - t) / frames * 1000.0


def main(n: int) -> None:
    import pyvista as pv
    from PySide6.QtWidgets import QApplication
    from pyvistaqt import QtInteractor

    from app.gui.views.cloud_view import with_interactive_lod
    from projects.outputs.inspection import decimate

    app = QApplication.instance() or QApplication([])
    rng = np.random.default_rng(0)
    xyz = (rng.random((n, 3)) * [40.0, 10.0, 8.0]).astype(np.float32)
    p = QtInteractor()
    p.interactor.resize(1200, 800)
    p.interactor.show()
    cloud = pv.PolyData(xyz)
    cloud["v"] = xyz[:, 2]
    p.add_points(cloud, scalars="v", point_size=2)
    p.reset_camera()
    p.render()
    base = frame_ms(p)
    p.clear()
    keep = decimate(n, 1_500_000)
    shown = pv.PolyData(xyz[keep])
    shown["v"] = xyz[keep, 2]
    actor = p.add_points(shown, scalars="v", point_size=2)
    with_interactive_lod(p, actor, shown)
    p.reset_camera()
    rw = p.render_window
    rw.SetDesiredUpdateRate(0.0001)  # still
    still = frame_ms(p)
    rw.SetDesiredUpdateRate(15.0)    # while the user rotates (VTK's default interactive rate)
    moving = frame_ms(p)
    print(f"{n:,} points, 1200x800 view, mean of 5 frames")
    print(f"plain pyvista, every point          {base:8.0f} ms/frame")
    print(f"BridgeSurvey view, still ({len(keep):,})   {still:8.0f} ms/frame   x{still / base:.2f}")
    print(f"BridgeSurvey view, moving (<=150 k)   {moving:8.0f} ms/frame   x{moving / base:.2f}")
    print(f"  RESULT: while moving {moving:.0f} ms/frame ({1000 / moving:.1f} fps), x{moving / base:.3f} of drawing "
          "every point")
    figures(points=n, shown=len(keep), plain_ms=base, still_ms=still, moving_ms=moving)
    p.close()
    del app


if __name__ == "__main__":
    _small, _args = small_mode()
    n = int(_args[0]) if _args else 50_000 if _small else 10_000_000
    if not os.environ.get("DISPLAY") and shutil.which("xvfb-run") and not os.environ.get("_BENCH_XVFB"):
        env = {**os.environ, "QT_QPA_PLATFORM": "xcb", "_BENCH_XVFB": "1"}
        sys.exit(subprocess.call(["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", sys.executable, __file__, str(n)],
                                 env=env))
    os.environ.setdefault("QT_QPA_PLATFORM", "xcb")
    main(n)

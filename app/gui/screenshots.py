"""Save a screenshot of every view of a campaign (the demo by default): ``./run screenshots [DEMO] [OUT]``.

Runs the real main window; needs a display with OpenGL for the 3-D view (``./run screenshots``
provides one with Xvfb).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path


def wait_jobs(app, win) -> None:
    while win.jobs.busy:  # sleep (it releases the GIL) and let the finished signals arrive
        time.sleep(0.02)
        app.processEvents()
    for _ in range(20):
        app.processEvents()


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    campaign = Path(argv[0] if argv else "demo-campaign")
    out = Path(argv[1] if len(argv) > 1 else "screenshots")
    out.mkdir(parents=True, exist_ok=True)
    from PySide6.QtWidgets import QApplication

    from app.gui.main_window import MainWindow

    app = QApplication.instance() or QApplication([])
    win = MainWindow(demo_dir=str(campaign))
    win.resize(1600, 1000)
    win.show()
    if not win.open_campaign(campaign):
        return 1
    app.processEvents()
    epochs = [e["epoch"] for e in win.status_data["epochs"]]
    label = epochs[len(epochs) // 2] if epochs else None
    shots = []

    def shot(name):
        for _ in range(10):
            app.processEvents()
        path = out / f"{len(shots) + 1:02d}-{name}.png"
        win.grab().save(str(path))
        shots.append(path)

    win.tree.select_key("reflector", "M3")
    win.tabs.setCurrentWidget(win.displacements)
    shot("displacements")
    win.displacements.target.setCurrentIndex(0)
    shot("displacements-all")
    win.session.select(epoch=label)
    win.tree.select_key("epoch", label)
    win.tabs.setCurrentWidget(win.map_view)
    shot("reflectance-map")
    win.session.select(reflector="M3")
    shot("reflectance-map-M3")
    win.commands.show_fine()
    wait_jobs(app, win)
    shot("fine-scan")
    win.tabs.setCurrentWidget(win.cloud_view)
    if win.cloud_view.show_btn.isEnabled():
        win.commands.show_cloud("intensity")
        wait_jobs(app, win)
        win.cloud_view.select_target("M3")
        shot("3d-intensity")
        win.commands.show_cloud("change")
        wait_jobs(app, win)
        shot("3d-change")
    win.tabs.setCurrentWidget(win.camera_view)
    shot("camera-crossval")
    win.commands.evaluate_stations(4.0, 1.5)
    wait_jobs(app, win)
    shot("stations")
    for p in shots:
        print(p)
    win.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())

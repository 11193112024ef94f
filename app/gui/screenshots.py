"""Save a screenshot of every tab of a campaign (the demo by default), on a laptop screen and on a
full-HD one: ``./run screenshots [DEMO] [OUT]`` writes ``OUT/1366x768/NN-name.png`` and
``OUT/1920x1080/NN-name.png``.

Runs the real main window, driven through its state and commands as a user would; needs a display
with OpenGL for the 3-D view (``./run screenshots`` provides one with Xvfb). Each job runs once; the
second screen size shows the same results again.
"""
from __future__ import annotations

import hashlib
import sys
import time
from pathlib import Path

from PySide6.QtWidgets import QApplication

from app.gui.main_window import MainWindow

SIZES = ((1366, 768), (1920, 1080))


def wait_jobs(app, win) -> None:
    while win.jobs.busy:  # sleep (it releases the GIL) and let the finished signals arrive
        time.sleep(0.02)
        app.processEvents()
    for _ in range(20):
        app.processEvents()


class Shooter:
    """Drives the window and saves what it shows; job results are kept for the second screen size."""

    def __init__(self, app, win, out: Path):
        self.app, self.win, self.out = app, win, out
        self.results: dict = {}
        self.paths: list[Path] = []
        outs = win.state.outputs
        outs.inspection.connect(lambda r: self.results.__setitem__("inspection", r))
        outs.stations.connect(lambda a, lay: self.results.__setitem__("stations", (a, lay)))
        outs.analysis.connect(lambda d: self.results.__setitem__("analysis", d))

    def pump(self, n: int = 15) -> None:
        for _ in range(n):
            self.app.processEvents()
            time.sleep(0.01)

    def shot(self, folder: Path, name: str) -> None:
        self.pump()
        path = folder / f"{len(list(folder.glob('*.png'))) + 1:02d}-{name}.png"
        self.win.grab().save(str(path))
        self.paths.append(path)

    def run(self, label: str, size: tuple[int, int]) -> None:
        win, st = self.win, self.win.state
        folder = self.out / f"{size[0]}x{size[1]}"
        folder.mkdir(parents=True, exist_ok=True)
        for old in folder.glob("*.png"):
            old.unlink()
        win.showNormal()
        win.resize(*size)
        self.pump(30)
        st.select(reflector="M3", focus=("reflector", "M3"))
        st.request_view("displacements")
        self.shot(folder, "displacements-M3")
        win.displacements.target.setCurrentIndex(0)
        self.shot(folder, "displacements-all")
        st.select(epoch=label, focus=("epoch", label))
        st.request_view("map")
        self.pump()
        win.map_view.fit(everything=True)
        self.shot(folder, "reflectance-map")
        win.map_view.zoom_to("M3")
        self.shot(folder, "reflectance-map-M3")
        st.select(reflector="M3")
        if "inspection" in self.results:
            st.request_view("fine")
            st.outputs.inspection.emit(self.results["inspection"])
        else:
            win.commands.show_fine()
            wait_jobs(self.app, win)
        self.shot(folder, "fine-scan")
        st.request_view("cloud")
        if win.cloud_view.show_btn.isEnabled():
            for mode in ("intensity", "change"):
                win.commands.show_cloud(mode)  # a job each time: the view holds one cloud
                wait_jobs(self.app, win)
                win.cloud_view.select_target("M3")
                self.shot(folder, f"3d-{mode}")
        st.request_view("camera")
        self.shot(folder, "camera-crossval")
        if "stations" in self.results:
            st.request_view("stations")
            st.outputs.stations.emit(*self.results["stations"])
        else:
            win.stations_view.grid.setValue(4.0)
            win.stations_view.request_evaluation()
            wait_jobs(self.app, win)
        self.shot(folder, "stations")
        if "analysis" in self.results:
            st.request_view("analysis")
            st.outputs.analysis.emit(self.results["analysis"])
        else:
            win.commands.run_analysis()
            wait_jobs(self.app, win)
        self.shot(folder, "analysis")


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    campaign = Path(argv[0] if argv else "demo-campaign")
    out = Path(argv[1] if len(argv) > 1 else "screenshots")
    out.mkdir(parents=True, exist_ok=True)


    app = QApplication.instance() or QApplication([])
    win = MainWindow(demo_dir=str(campaign))
    win.show()
    if not win.open_campaign(campaign):
        return 1
    app.processEvents()
    epochs = win.state.snapshot.epochs
    label = epochs[len(epochs) // 2] if epochs else None
    shooter = Shooter(app, win, out)
    for size in SIZES:
        shooter.run(label, size)
    digests: dict[str, Path] = {}
    same = []
    for p in shooter.paths:
        d = hashlib.sha256(p.read_bytes()).hexdigest()
        if d in digests:
            same.append(f"{p} is identical to {digests[d]}")
        digests[d] = p
        print(p)
    win.close()
    for line in same:
        print(f"screenshots: {line}", file=sys.stderr)
    return 1 if same else 0


if __name__ == "__main__":
    sys.exit(main())

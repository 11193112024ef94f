"""A synthetic image set of a dual-camera installation, laid out as a surveyor would bring it.

zhang/                  the sub-camera's board at tilted poses (Zhang calibration)
calibration/main, sub/  rest frame first, then H rig motions with both targets still
measurement/main, sub/  the monitoring frames (rig drifting, the main target moving)
pattern.csv             main-target feature coordinates (x_mm, y_mm; y up)
times.csv               frame, timestamp of the measurement frames
truth.csv               frame, timestamp, true vertical displacement and the false one (mm)
"""
from __future__ import annotations

import datetime as dt
import os
from pathlib import Path

import cv2
import numpy as np

from common.files import write_atomic
from common.progress import ProgressCallback, report
from vision.simulate.motions import calibration_motions, pan_tilt_drift
from vision.simulate.rig import RigGeometry, SyntheticRig


def _write_png(path: Path, img: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise OSError(f"{path}: PNG encoding failed")
    write_atomic(path, buf.tobytes())


def write_dualcam_dataset(folder: str | os.PathLike, *, geometry: RigGeometry | None = None, n_zhang: int = 10,
                          n_calibration: int = 21, n_frames: int = 24, sag_mm: float = 4.0,
                          start: dt.datetime = dt.datetime(2026, 3, 2, 9, 0, tzinfo=dt.UTC),
                          interval_s: float = 3600.0, seed: int = 3,
                          progress: ProgressCallback | None = None) -> dict:
    """Render the data set; returns what the CLI needs (paths, board and pattern)."""
    g = geometry or RigGeometry.laboratory()
    rig = SyntheticRig(g)
    rng = np.random.default_rng(seed)
    root = Path(folder)
    dirs = {k: root / k for k in ("zhang", "calibration/main", "calibration/sub", "measurement/main",
                                  "measurement/sub")}
    for d in dirs.values():
        d.mkdir(parents=True, exist_ok=True)
    total = n_zhang + 2 * (n_calibration + 1) + 2 * n_frames
    done = 0

    def tick(msg):
        nonlocal done
        done += 1
        report(progress, done / total, msg)

    for k, B in enumerate(rig.zhang_poses(n_zhang, rng=rng)):
        _write_png(dirs["zhang"] / f"board_{k:03d}.png", rig.render_board_view(B, noise=0.004, rng=rng))
        tick("Zhang views")
    for k, P in enumerate(calibration_motions(n_calibration, rotation_rad=3e-3, translation_m=0.005, rng=rng)):
        _write_png(dirs["calibration/main"] / f"frame_{k:04d}.png", rig.render_main(P, noise=0.004, rng=rng))
        _write_png(dirs["calibration/sub"] / f"frame_{k:04d}.png", rig.render_sub(P, noise=0.004, rng=rng))
        tick("calibration frames")
        tick("calibration frames")
    poses = pan_tilt_drift(n_frames)
    sag = -sag_mm / 1000.0 * np.sin(np.linspace(0, np.pi / 2, n_frames))
    truth_rows, time_rows = ["frame,timestamp,true_vertical_mm,false_vertical_mm"], ["frame,timestamp"]
    for k, (P, dy) in enumerate(zip(poses, sag, strict=False)):
        disp = np.array([0.0, dy])
        _write_png(dirs["measurement/main"] / f"frame_{k:04d}.png", rig.render_main(P, disp, noise=0.004, rng=rng))
        _write_png(dirs["measurement/sub"] / f"frame_{k:04d}.png", rig.render_sub(P, noise=0.004, rng=rng))
        moved = rig.main_image_points(P, disp) - rig.main_image_points(np.eye(4))
        stamp = (start + dt.timedelta(seconds=k * interval_s)).isoformat()
        false_v = -np.mean(moved[:, 1]) * g.main_fov_m / g.resolution[0] * 1e3 - dy * 1e3
        truth_rows.append(f"{k},{stamp},{dy * 1e3:.4f},{false_v:.4f}")
        time_rows.append(f"{k},{stamp}")
        tick("measurement frames")
        tick("measurement frames")
    write_atomic(root / "pattern.csv", "x_mm,y_mm\n" + "\n".join(f"{x * 1e3:.3f},{y * 1e3:.3f}"
                                                                  for x, y in g.main_pattern_m) + "\n")
    write_atomic(root / "truth.csv", "\n".join(truth_rows) + "\n")
    write_atomic(root / "times.csv", "\n".join(time_rows) + "\n")
    nc, nr = g.board.inner_corners
    return {"folder": root, "board": f"{nc}x{nr}", "square_mm": g.board.square_m * 1e3,
            "pattern": root / "pattern.csv", "truth": root / "truth.csv", "times": root / "times.csv"}

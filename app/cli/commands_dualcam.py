"""The dual-camera commands: calibrate a set-up from images, measure displacements, simulate a data set."""
from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from app.cli.progress import progress_bar
from common.errors import InputError, ProcessingError
from common.files import write_atomic
from projects.store.campaign import parse_datetime
from vision.compensation import calibrate_dual_camera, measure_dual_camera
from vision.images import detect_boards, detect_sequence, list_images
from vision.setup_io import load_setup, save_setup
from vision.simulate.images import write_dualcam_dataset
from vision.simulate.rig import Checkerboard
from vision.sub_camera import calibrate_intrinsics

if TYPE_CHECKING:
    import numpy as np


def _board(text: str) -> tuple[int, int]:
    try:
        c, r = (int(v) for v in text.lower().split("x"))
        if c < 2 or r < 2:
            raise ValueError
        return c, r
    except ValueError:
        raise InputError(f"--board expects the inner corners as COLSxROWS (e.g. 20x12), got {text!r}") from None


def _pattern(path: Path) -> np.ndarray:
    try:
        rows = [ln.split(",") for ln in path.read_text().splitlines()[1:] if ln.strip()]
        pts = np.array([[float(a), float(b)] for a, b, *_ in rows]) / 1000.0
    except FileNotFoundError:
        raise InputError(f"{path}: pattern file not found") from None
    except (ValueError, UnicodeDecodeError):
        raise InputError(f"{path}: expected a header and rows x_mm,y_mm") from None
    if len(pts) < 3:
        raise InputError(f"{path}: the main target needs at least 3 features, found {len(pts)}")
    return pts


def cmd_calibrate(args) -> int:
    corners = _board(args.board)
    pattern = _pattern(args.pattern)
    board = Checkerboard((corners[0] + 1, corners[1] + 1), args.square_mm / 1000.0)
    zhang = list_images(args.zhang)
    views, size = detect_boards(zhang, corners)
    if len(views) < 3:
        raise ProcessingError(f"{args.zhang}: the board ({args.board} inner corners) was found in {len(views)} of "
                              f"{len(zhang)} images; Zhang's calibration needs at least 3")
    intr = calibrate_intrinsics(board.object_points(), views, size)
    with progress_bar("calibration frames") as cb:
        uv, sub = detect_sequence(list_images(args.main), list_images(args.sub), pattern_m=pattern,
                                  inner_corners=corners, progress=cb)
    setup = calibrate_dual_camera(uv, sub, pattern_m=pattern, board_points_m=board.object_points(), intrinsics=intr)
    save_setup(setup, args.out)
    cal = setup.calibration
    print(f"sub-camera: Zhang from {len(views)} of {len(zhang)} views, reprojection RMS {intr.rms_px:.3f} px")
    print(f"main target: {setup.target.mm_per_px:.4f} mm/px, affine fit {setup.target.residual_px:.3f} px")
    print(f"dual calibration: {cal.n_motions} motions, misfit {np.mean(cal.residual_px):.2f} px "
          f"({np.mean(cal.residual_px) * setup.target.mm_per_px:.3f} mm)")
    print(f"wrote {args.out}")
    return 0


def cmd_measure(args) -> int:
    setup = load_setup(args.setup)
    nc_nr = _infer_board(setup)
    main, sub = list_images(args.main), list_images(args.sub)
    times = _times(args.times, len(main)) if args.times else [""] * len(main)
    with progress_bar("measurement frames") as cb:
        uv, corners = detect_sequence(main, sub, pattern_m=setup.target.pattern_m, inner_corners=nc_nr, progress=cb)
    res = measure_dual_camera(setup, uv, corners)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["timestamp", "frame", "displacement_mm", "horizontal_mm", "sigma_mm", "single_camera_mm",
                "false_mm", "flags"])
    for k in range(len(main)):
        v = lambda a: "" if not np.isfinite(a) else f"{a * 1e3:.4f}"  # noqa: E731
        w.writerow([times[k], main[k].name, v(res.displacement_m[k, 1]), v(res.displacement_m[k, 0]),
                    v(res.sigma_m[k, 1]), v(res.single_camera_m[k, 1]), v(res.false_displacement_m[k, 1]),
                    ";".join(res.flags[k])])
    write_atomic(args.out, buf.getvalue())
    ok = res.valid.sum()
    false = np.nanmax(np.abs(res.false_displacement_m[:, 1])) * 1e3 if ok else float("nan")
    print(f"{ok} of {len(main)} frames measured; false displacement removed up to {false:.2f} mm; "
          f"median sigma {np.nanmedian(res.sigma_m[:, 1]) * 1e3:.3f} mm")
    print(f"wrote {args.out}")
    return 0


def _infer_board(setup) -> tuple[int, int]:
    """Inner corners (cols, rows) from the stored board points (row by row)."""
    pts = setup.board_points_m
    cols = int(np.sum(np.isclose(pts[:, 1], pts[0, 1])))
    return cols, len(pts) // cols


def _times(path: Path, n: int) -> list[str]:
    try:
        rows = [ln.split(",") for ln in path.read_text().splitlines()[1:] if ln.strip()]
        out = [parse_datetime(r[1].strip()) for r in rows]
    except FileNotFoundError:
        raise InputError(f"{path}: times file not found") from None
    except (IndexError, UnicodeDecodeError):
        raise InputError(f"{path}: expected a header and rows frame,timestamp") from None
    if len(out) != n:
        raise InputError(f"{path}: {len(out)} timestamps for {n} frames")
    return out


def cmd_simulate(args) -> int:
    with progress_bar("rendering") as cb:
        info = write_dualcam_dataset(args.dir, n_frames=args.frames, n_calibration=args.motions, progress=cb)
    d = info["folder"]
    print(f"wrote a dual-camera image set with ground truth in {d}; try:")
    print(f"  bridgesurvey dualcam calibrate --zhang {d}/zhang --main {d}/calibration/main --sub {d}/calibration/sub "
          f"--pattern {info['pattern']} --board {info['board']} --square-mm {info['square_mm']:g} --out {d}/setup.json")
    print(f"  bridgesurvey dualcam measure --setup {d}/setup.json --main {d}/measurement/main "
          f"--sub {d}/measurement/sub --times {info['times']} --out {d}/series.csv")
    return 0

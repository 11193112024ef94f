"""The dual-camera commands: calibrate a set-up from images, measure displacements, simulate a data set."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from app.cli.args import input_file, input_folder, output_file, output_folder
from app.cli.progress import progress_bar

if TYPE_CHECKING:
    import numpy as np


def register(sub) -> None:
    p = sub.add_parser("dualcam", help="the dual-camera method from images: calibrate, measure, simulate",
                       description="Camera-motion compensated displacement of a main target (circles) watched by "
                                   "a main camera whose motion a rigidly attached sub-camera measures on a "
                                   "checkerboard. Frames are image files in name order.")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    q = actions.add_parser("calibrate", help="calibrate a set-up: Zhang views, then the rig moved with both "
                                             "targets still (first frame = rest)")
    input_folder(q, "--zhang", required=True, help="folder of sub-camera images of the board, tilted")
    input_folder(q, "--main", required=True, help="folder of main-camera calibration frames")
    input_folder(q, "--sub", required=True, help="folder of sub-camera calibration frames")
    input_file(q, "--pattern", required=True, help="CSV x_mm,y_mm of the main target's features (y up)")
    q.add_argument("--board", required=True, help="inner corners of the checkerboard, COLSxROWS (e.g. 20x12)")
    q.add_argument("--square-mm", type=float, required=True, help="checkerboard square size")
    output_file(q, "--out", required=True, help="set-up file to write (JSON)")
    q.set_defaults(func=cmd_calibrate)
    q = actions.add_parser("measure", help="compensated displacement of every measurement frame")
    input_file(q, "--setup", required=True, help="the set-up file 'dualcam calibrate' wrote")
    input_folder(q, "--main", required=True, help="folder of main-camera measurement frames")
    input_folder(q, "--sub", required=True, help="folder of sub-camera measurement frames (same order)")
    input_file(q, "--times", default=None, help="CSV frame,timestamp (default: frame numbers only)")
    output_file(q, "--out", required=True, help="series CSV (readable by 'camera import')")
    q.set_defaults(func=cmd_measure)
    q = actions.add_parser("simulate", help="render a synthetic image set with ground truth (lab geometry)")
    output_folder(q, "dir", metavar="FOLDER", help="folder to write the image set into (created when missing)")
    q.add_argument("--frames", type=int, default=24, help="measurement frames (24)")
    q.add_argument("--motions", type=int, default=21, help="calibration motions of the rig (21)")
    q.set_defaults(func=cmd_simulate)


def _board(text: str) -> tuple[int, int]:
    from common.errors import InputError

    try:
        c, r = (int(v) for v in text.lower().split("x"))
        if c < 2 or r < 2:
            raise ValueError
        return c, r
    except ValueError:
        raise InputError(f"--board expects the inner corners as COLSxROWS (e.g. 20x12), got {text!r}") from None


def _pattern(path: Path) -> np.ndarray:
    import numpy as np

    from common.errors import InputError

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
    import numpy as np

    from common.errors import ProcessingError
    from vision.compensation import calibrate_dual_camera
    from vision.images import detect_boards, detect_sequence, list_images
    from vision.setup_io import save_setup
    from vision.simulate.rig import Checkerboard
    from vision.sub_camera import calibrate_intrinsics

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
    import csv
    import io

    import numpy as np

    from common.files import write_atomic
    from vision.compensation import measure_dual_camera
    from vision.images import detect_sequence, list_images
    from vision.setup_io import load_setup

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
    import numpy as np

    pts = setup.board_points_m
    cols = int(np.sum(np.isclose(pts[:, 1], pts[0, 1])))
    return cols, len(pts) // cols


def _times(path: Path, n: int) -> list[str]:
    from common.errors import InputError
    from projects.store.campaign import parse_datetime

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
    from vision.simulate.images import write_dualcam_dataset

    with progress_bar("rendering") as cb:
        info = write_dualcam_dataset(args.dir, n_frames=args.frames, n_calibration=args.motions, progress=cb)
    d = info["folder"]
    print(f"wrote a dual-camera image set with ground truth in {d}; try:")
    print(f"  bridgesurvey dualcam calibrate --zhang {d}/zhang --main {d}/calibration/main --sub {d}/calibration/sub "
          f"--pattern {info['pattern']} --board {info['board']} --square-mm {info['square_mm']:g} --out {d}/setup.json")
    print(f"  bridgesurvey dualcam measure --setup {d}/setup.json --main {d}/measurement/main "
          f"--sub {d}/measurement/sub --times {info['times']} --out {d}/series.csv")
    return 0

"""The parsers of the dual-camera commands: calibrate a set-up from images, measure displacements, simulate a data set.

They name each command's function in app.cli.commands_dualcam (``func``), which the program imports when the command
runs: building them imports nothing else.
"""
from __future__ import annotations

from app.cli.args import input_file, input_folder, output_file, output_folder


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
    q.set_defaults(func="cmd_calibrate")
    q = actions.add_parser("measure", help="compensated displacement of every measurement frame")
    input_file(q, "--setup", required=True, help="the set-up file 'dualcam calibrate' wrote")
    input_folder(q, "--main", required=True, help="folder of main-camera measurement frames")
    input_folder(q, "--sub", required=True, help="folder of sub-camera measurement frames (same order)")
    input_file(q, "--times", default=None, help="CSV frame,timestamp (default: frame numbers only)")
    output_file(q, "--out", required=True, help="series CSV (readable by 'camera import')")
    q.set_defaults(func="cmd_measure")
    q = actions.add_parser("simulate", help="render a synthetic image set with ground truth (lab geometry)")
    output_folder(q, "dir", metavar="FOLDER", help="folder to write the image set into (created when missing)")
    q.add_argument("--frames", type=int, default=24, help="measurement frames (24)")
    q.add_argument("--motions", type=int, default=21, help="calibration motions of the rig (21)")
    q.set_defaults(func="cmd_simulate")

"""Saving and loading a calibrated dual-camera set-up (versioned JSON).

A set-up is calibrated once (the rig moved H times with both targets still) and then used for
every measurement frame, so it is kept as a file of its own::

    {"format": "bridgesurvey-dualcam-setup", "version": 1, "target": {...}, "intrinsics": {...},
     "board_points_m": [...], "rest_B_ws_to_cs": [...], "rest_main_uv": [...], "calibration": {...}}
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from common.errors import InputError
from common.files import write_atomic
from vision.compensation import DualCalibration, DualCameraSetup
from vision.main_camera import AffineTargetModel
from vision.sub_camera import Intrinsics

FORMAT = "bridgesurvey-dualcam-setup"
VERSION = 1


def setup_to_json(s: DualCameraSetup) -> dict:
    """A dual-camera set-up as its versioned JSON document."""
    t, i, c = s.target, s.intrinsics, s.calibration
    return {
        "format": FORMAT, "version": VERSION,
        "target": {"Bt": t.Bt.tolist(), "b": t.b.tolist(), "residual_px": t.residual_px,
                   "pattern_m": t.pattern_m.tolist()},
        "intrinsics": {"K": i.K.tolist(), "distortion": i.distortion.tolist(), "rms_px": i.rms_px,
                       "image_size": list(i.image_size), "n_views": i.n_views},
        "board_points_m": s.board_points_m.tolist(),
        "rest_B_ws_to_cs": s.rest_B_ws_to_cs.tolist(),
        "rest_main_uv": s.rest_main_uv.tolist(),
        "calibration": {"Bbar": c.Bbar.tolist(), "X_cs1": c.X_cs1.tolist(), "residual_px": c.residual_px.tolist(),
                        "n_motions": c.n_motions, "false_rms_px": c.false_rms_px},
    }


def setup_from_json(d: dict, *, source: str = "set-up") -> DualCameraSetup:
    """A dual-camera set-up from its JSON document (a newer format version is refused)."""
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise InputError(f"{source}: not a BridgeSurvey dual-camera set-up file")
    if int(d.get("version", 0)) > VERSION:
        raise InputError(f"{source}: set-up format {d['version']} is newer than this BridgeSurvey reads ({VERSION}); "
                         "update BridgeSurvey")
    try:
        a = lambda v: np.asarray(v, dtype=float)  # noqa: E731
        t, i, c = d["target"], d["intrinsics"], d["calibration"]
        return DualCameraSetup(
            target=AffineTargetModel(a(t["Bt"]), a(t["b"]), float(t["residual_px"]), a(t["pattern_m"])),
            intrinsics=Intrinsics(a(i["K"]), a(i["distortion"]), float(i["rms_px"]), tuple(i["image_size"]),
                                  int(i["n_views"])),
            board_points_m=a(d["board_points_m"]), rest_B_ws_to_cs=a(d["rest_B_ws_to_cs"]),
            rest_main_uv=a(d["rest_main_uv"]),
            calibration=DualCalibration(a(c["Bbar"]), a(c["X_cs1"]), a(c["residual_px"]), int(c["n_motions"]),
                                        float(c["false_rms_px"])))
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{source}: incomplete or damaged set-up file ({exc})") from None


def save_setup(s: DualCameraSetup, path: str | os.PathLike) -> Path:
    """Write a set-up JSON file atomically; returns its path."""
    return write_atomic(path, json.dumps(setup_to_json(s), indent=1) + "\n")


def load_setup(path: str | os.PathLike) -> DualCameraSetup:
    """Read a set-up JSON file (one-line errors for a missing, damaged or newer file)."""
    p = Path(path)
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{p}: set-up file not found") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: not a JSON set-up file ({exc})") from None
    return setup_from_json(d, source=str(p))

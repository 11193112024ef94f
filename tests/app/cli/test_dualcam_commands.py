"""bridgesurvey dualcam: simulate an image set, calibrate, measure against ground truth; clean refusals."""
from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from app.cli.main import main
from tests.app.cli.conftest import error_lines


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    d = tmp_path_factory.mktemp("dualcam") / "set"
    assert main(["dualcam", "simulate", str(d), "--frames", "8", "--motions", "14"]) == 0
    return d


def _calibrate(d, out, **over):
    args = {"--zhang": d / "zhang", "--main": d / "calibration/main", "--sub": d / "calibration/sub",
            "--pattern": d / "pattern.csv", "--board": "20x12", "--square-mm": "4", "--out": out, **over}
    return main(["dualcam", "calibrate"] + [str(x) for kv in args.items() for x in kv])


@pytest.mark.slow
def test_calibrate_and_measure_reproduce_the_truth(images, tmp_path, capsys):
    d = images
    assert _calibrate(d, tmp_path / "setup.json") == 0
    assert "dual calibration: 14 motions" in capsys.readouterr().out
    assert main(["dualcam", "measure", "--setup", str(tmp_path / "setup.json"), "--main", str(d / "measurement/main"),
                 "--sub", str(d / "measurement/sub"), "--times", str(d / "times.csv"),
                 "--out", str(tmp_path / "series.csv")]) == 0
    got = list(csv.DictReader(open(tmp_path / "series.csv")))
    truth = list(csv.DictReader(open(d / "truth.csv")))
    err = np.array([float(g["displacement_mm"]) - float(t["true_vertical_mm"])
                    for g, t in zip(got, truth, strict=True)])
    sig = np.array([float(g["sigma_mm"]) for g in got])
    false = np.array([float(t["false_vertical_mm"]) for t in truth])
    assert np.abs(false).max() > 3.0            # the rig's drift fakes millimetres...
    assert np.abs(err).max() < 1.1              # ...which the sub-camera removes (dissertation: 1.1 mm of 44)
    assert np.mean(np.abs(err) <= 2.5 * sig) >= 0.85
    assert got[0]["timestamp"].startswith("2026-03-02T09:00")
    # the series is what 'camera import' reads
    from vision.series import read_camera_series

    s = read_camera_series(tmp_path / "series.csv")
    assert len(s) == len(got) and s.column == "displacement_mm"


def test_refusals_name_the_file(images, tmp_path, capsys):
    d = images
    bad = tmp_path / "copy"
    shutil.copytree(d / "calibration", bad)
    (bad / "main" / "frame_0003.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    cases = [
        (lambda: _calibrate(d, tmp_path / "s.json", **{"--board": "20by12"}), "COLSxROWS"),
        (lambda: _calibrate(d, tmp_path / "s.json", **{"--zhang": tmp_path / "none"}), "none: no such folder"),
        (lambda: _calibrate(d, tmp_path / "s.json", **{"--main": bad / "main", "--sub": bad / "sub"}),
         "frame_0003.png: not a readable image"),
        (lambda: _calibrate(d, tmp_path / "s.json", **{"--pattern": d / "truth.csv"}), "x_mm,y_mm"),
    ]
    for run, message in cases:
        capsys.readouterr()
        assert run() == 1
        err = capsys.readouterr().err.strip()
        assert message in err and len(error_lines(err)) == 1
        assert not (tmp_path / "s.json").exists()
    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps({"format": "bridgesurvey-dualcam-setup", "version": 99}))
    assert main(["dualcam", "measure", "--setup", str(newer), "--main", str(d / "measurement/main"), "--sub",
                 str(d / "measurement/sub"), "--out", str(tmp_path / "o.csv")]) == 1
    assert "newer" in capsys.readouterr().err

"""``bridgesurvey info`` and ``convert`` on every sample file in tests/data and on every writable format."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from lidar.io import read_scans, write_scan
from tests.lidar.io.fuzz_cases import sample_scan

DATA = Path(__file__).resolve().parents[2] / "data"
GOOD = sorted(p for p in DATA.rglob("*") if p.suffix in (".las", ".laz", ".e57") and p.name not in
              ("bad-crc.e57", "ZeroPoints.e57"))
BAD = [DATA / "e57" / "bad-crc.e57", DATA / "e57" / "ZeroPoints.e57"]
SUFFIXES = [".las", ".laz", ".e57", ".ply", ".pcd", ".ptx", ".pts", ".xyz"]


@pytest.mark.parametrize("path", GOOD, ids=lambda p: p.name)
def test_info_describes_every_sample_file(path, capsys):
    assert main(["info", str(path), "--json"]) == 0
    (header,) = json.loads(capsys.readouterr().out)
    assert not header["stats"] and [s["points"] for s in header["scans"]] == [len(s) for s in read_scans(path)]
    assert main(["info", str(path), "--stats", "--json"]) == 0
    (info,) = json.loads(capsys.readouterr().out)
    scans = read_scans(path)
    assert info["path"] == str(path)
    assert info["format"] in ("LAS", "LAZ", "E57")
    assert [s["points"] for s in info["scans"]] == [len(s) for s in scans]
    for s, scan in zip(info["scans"], scans, strict=False):
        np.testing.assert_allclose(s["bounds_min"], scan.xyz_socs.min(axis=0))
        assert (s["intensity_raw_range"] is None) == (scan.intensity_raw is None)
    for flags in ([], ["--full"]):
        assert main(["info", str(path), *flags]) == 0
        text = capsys.readouterr().out
        assert str(path) in text and "points" in text


@pytest.mark.parametrize("path", BAD, ids=lambda p: p.name)
def test_info_refuses_damaged_samples_in_one_line(path, capsys):
    assert main(["info", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0]


def test_info_reports_the_angular_step_and_problems(tmp_path, capsys):
    # a 0.05-degree grid seen from the scanner at 10 m, with one duplicated and one NaN point
    th, ph = np.meshgrid(np.radians(np.arange(80, 90, 0.05)), np.radians(np.arange(0, 10, 0.05)))
    d = np.column_stack([(np.sin(th) * np.cos(ph)).ravel(), (np.sin(th) * np.sin(ph)).ravel(), np.cos(th).ravel()])
    xyz = np.vstack([d * 10.0, d[:1] * 10.0, [[np.nan, 0, 0]]])
    p = tmp_path / "grid.xyz"
    np.savetxt(p, np.column_stack([xyz, np.linspace(0, 1, len(xyz))]))
    assert main(["info", str(p), "--json"]) == 0
    (scan,) = json.loads(capsys.readouterr().out)[0]["scans"]
    assert scan["angular_step_deg"] == pytest.approx(0.05, rel=0.1)
    assert scan["spacing_at_10m_mm"] == pytest.approx(8.7, rel=0.1)
    assert scan["duplicate_points"] == 1
    assert any("1 NaN" in s for s in scan["problems"])


@pytest.mark.parametrize("path", GOOD, ids=lambda p: p.name)
@pytest.mark.parametrize("suffix", SUFFIXES)
def test_convert_every_sample_to_every_format(path, suffix, tmp_path, capsys):
    out = tmp_path / f"out{suffix}"
    assert main(["convert", str(path), str(out)]) == 0
    before, after = read_scans(path), read_scans(out)
    assert len(after) == len(before)
    tol = 2e-5 if suffix in (".xyz", ".pts", ".ptx", ".las", ".laz") else 1e-9
    for a, b in zip(before, after, strict=False):
        np.testing.assert_allclose(b.xyz_socs, a.xyz_socs, atol=max(tol, 1e-5 * np.abs(a.xyz_socs).max() * 1e-6))
        if a.intensity is not None:
            np.testing.assert_allclose(b.intensity, a.intensity, atol=2e-4)


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_convert_keeps_pose_and_raw_intensity(suffix, tmp_path, capsys):
    scan = sample_scan()
    src = write_scan(scan, tmp_path / "src.e57")
    out = tmp_path / f"out{suffix}"
    assert main(["convert", str(src), str(out)]) == 0
    (back,) = read_scans(out)
    if suffix == ".ptx":  # PTX holds Leica's 0-1 intensity: the normalised values are kept
        np.testing.assert_allclose(back.intensity, scan.intensity, atol=1e-6)
    else:
        np.testing.assert_allclose(back.intensity_raw, scan.intensity_raw, rtol=1e-6)
    if suffix == ".pts":
        assert back.pose is None
        assert "the pose is not: PTS has no place for it" in capsys.readouterr().out
    else:
        np.testing.assert_allclose(back.pose, scan.pose, atol=1e-9)
        assert "pose and intensity kept" in capsys.readouterr().out


def test_convert_refusals(tmp_path, capsys):
    src = write_scan(sample_scan(), tmp_path / "a.las")
    for argv, words in ((["convert", str(src), str(tmp_path / "x.obj")], "cannot write"),
                        (["convert", str(src), str(src)], "already exists"),
                        (["convert", str(BAD[0]), str(tmp_path / "y.las")], "checksum"),
                        (["convert", str(src), str(tmp_path / "z.las"), "--scan", "3"], "--scan must be")):
        assert main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
    assert not (tmp_path / "y.las").exists()


def test_a_closed_pipe_ends_quietly(tmp_path):
    """'bridgesurvey info MANY | head -1': no BrokenPipe traceback, exit 141 like other CLIs."""
    import subprocess
    import sys

    files = [str(GOOD[0])] * 300
    proc = subprocess.Popen([sys.executable, "-m", "app.cli.main", "info", *files], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=Path(__file__).resolve().parents[3])
    proc.stdout.readline()
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert "Traceback" not in err and "BrokenPipe" not in err

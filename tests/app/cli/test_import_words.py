"""What an import says (issue 41 item 7): a truncated LAZ gets our one line only, an XYZ file's NaN points are
counted at import, and a layout with two reference targets is warned about at init."""
import subprocess
import sys
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "data"


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, args)], capture_output=True, text=True)


def test_a_truncated_laz_prints_only_our_line(tmp_path):
    data = (DATA / "las" / "simple.laz").read_bytes()
    (tmp_path / "cut.laz").write_bytes(data[:int(len(data) * 0.7)])
    r = _cli("info", tmp_path / "cut.laz")
    assert r.returncode == 1
    assert r.stderr.strip().splitlines() == [f"bridgesurvey: error: {tmp_path / 'cut.laz'}: damaged point data "
                                             "(IoError: failed to fill whole buffer)"]
    r = _cli("-v", "info", tmp_path / "cut.laz")  # asked for: the library's own line too
    assert r.returncode == 1 and "laspy" in r.stderr


def test_two_reference_targets_are_warned_about_and_nan_points_counted_at_import(tmp_path):
    (tmp_path / "layout.csv").write_text("id,group,x,y,z\nR1,reference,0,0,2\nR2,reference,0,3,2\n"
                                         "M1,measurement,10,1.5,6\nM2,measurement,20,1.5,6\nM3,measurement,30,1.5,6\n")
    r = _cli("init", tmp_path / "camp", "--name", "x", "--layout", tmp_path / "layout.csv")
    assert r.returncode == 0, r.stderr
    assert "warning: the layout has only 2 reference targets (R1, R2): when one of them moves" in r.stdout
    rng = np.random.default_rng(0)
    lines = [f"{x:.3f} {y:.3f} {z:.3f} {i:.3f}" for (x, y, z), i in zip(rng.uniform(-20, 20, (1000, 3)),
                                                                          rng.uniform(0, 1, 1000), strict=True)]
    for k in range(0, 1000, 50):
        lines[k] = "nan nan nan 0.5"
    (tmp_path / "coarse.xyz").write_text("\n".join(lines) + "\n")
    r = _cli("add-epoch", tmp_path / "camp", "--date", "2026-03-02T09:00", "--coarse", tmp_path / "coarse.xyz")
    assert r.returncode == 0, r.stderr
    assert (f"note: {tmp_path / 'coarse.xyz'}: 20 of 1,000 points (2.0 %) have a NaN or infinite coordinate and "
            "are left out") in r.stdout.splitlines()
    r = _cli("status", tmp_path / "camp")
    assert "warning: the layout has only 2 reference targets" in r.stdout

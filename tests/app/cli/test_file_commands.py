"""The single-file commands, end to end through the documented command line."""
import json

import numpy as np
import pytest

from app.cli.main import main
from tests.app.cli.conftest import error_lines


@pytest.fixture(scope="module")
def visit(tmp_path_factory):
    folder = tmp_path_factory.mktemp("visit")
    assert main(["simulate", str(folder), "--cable-tie", "R1", "--midspan-mm", "-4", "--coarse-step-deg", "0.05"]) == 0
    return folder


def test_detect_plan_simulate_centroids_loop(visit, capsys):
    assert main(["detect", str(visit / "coarse.laz"), "--layout", str(visit / "layout.csv"), "--json",
                 "--png", str(visit / "map.png")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {t["id"] for t in out["targets"] if t["status"] == "detected"} == {f"R{k}" for k in range(1, 5)} | \
        {f"M{k}" for k in range(1, 6)}
    assert (visit / "map.png").stat().st_size > 10_000
    plan = visit / "plan.json"
    assert main(["plan-file", str(visit / "coarse.laz"), "--layout", str(visit / "layout.csv"), "--out", str(plan),
                 "--epoch", "W1"]) == 0
    capsys.readouterr()
    assert json.loads(plan.read_text())["epoch"] == "W1"
    assert main(["simulate", str(visit), "--fine", str(plan)]) == 0
    capsys.readouterr()
    assert main(["centroids", str(visit / "fine.laz"), "--plan", str(plan), "--json"]) == 0
    rows = {r["reflector"]: r for r in json.loads(capsys.readouterr().out)}
    truth = json.loads((visit / "truth.json").read_text())
    for t in truth["targets"]:
        r = rows[t["id"]]
        assert r["found"]
        err = np.linalg.norm(np.array([r["x"], r["y"], r["z"]]) - np.array(t["centre_socs_m"]))
        assert err < 0.001, t["id"]
    assert "second_bright_object" in rows["R1"]["flags"]


@pytest.mark.parametrize("argv, message", [
    (["detect", "{v}/absent.laz", "--layout", "{v}/layout.csv"], "absent.laz: no such file"),
    (["detect", "{v}/coarse.laz", "--layout", "{v}/nolayout.csv"], "nolayout.csv: no such file"),
    (["centroids", "{v}/coarse.laz", "--plan", "{v}/layout.csv"], "layout.csv: not a JSON plan"),
    (["simulate", "{v}/x", "--position", "1,2"], "--position expects x,y,z"),
])
def test_bad_input_is_one_clear_line(visit, capsys, argv, message):
    code = main([a.format(v=visit) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 1 and message in err and len(error_lines(err)) == 1


def test_layout_missing_a_column(visit, tmp_path, capsys):
    bad = tmp_path / "layout.csv"
    bad.write_text("id,group,x,y\nR1,reference,0,0\n")
    assert main(["detect", str(visit / "coarse.laz"), "--layout", str(bad)]) == 1
    assert "missing column(s) z" in capsys.readouterr().err


def test_usage_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["detect"])
    assert e.value.code == 2


def test_planning_from_a_las_file_labels_with_scikit_image(visit, tmp_path, capsys):
    """plan-file labels the coarse map's blobs with scikit-image, the library the user named (issue 43; its import
    costs the command about 0.3 s of the 0.58 s it lost against the hand-written labelling, issue 27's figure)."""
    from tests.app.cli.test_conventions import _modules_after

    las = tmp_path / "coarse.las"
    assert main(["convert", str(visit / "coarse.laz"), str(las)]) == 0
    capsys.readouterr()
    out = tmp_path / "plan.json"
    r = _modules_after(f"from app.cli.main import main\nrc = main(['plan-file', {str(las)!r}, '--layout', "
                       f"{str(visit / 'layout.csv')!r}, '--out', {str(out)!r}])\nassert rc == 0, rc")
    assert "skimage.measure" in r["loaded"]
    assert len(json.loads(out.read_text())["rois"]) >= 9  # every target of the layout planned

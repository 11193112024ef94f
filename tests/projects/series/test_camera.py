"""Camera series in a campaign: import, cross-validation with the LiDAR epochs, and refusals."""
from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli.main import main
from projects.store.campaign import Campaign
from tests.projects.campaign_helpers import snapshot
from vision.simulate.series import simulate_series, write_series_csv

DATES = ("2026-03-02T09:00:00", "2026-03-09T10:00:00", "2026-03-16T08:30:00")
TRUTH_MM = (0.0, -4.0, -7.0)  # midspan (M3) displacement of the three visits, against the first


def _ns(iso):
    return np.datetime64(iso, "ns").astype(np.int64)


def truth(t):
    return np.interp(t, [_ns(d) for d in DATES], TRUTH_MM)


@pytest.fixture
def camera_csv(tmp_path):
    t, v = simulate_series(_ns("2026-02-28T00:00"), _ns("2026-03-18T00:00"), truth, noise_mm=0.1,
                           zero_offset_mm=12.0, outages=[(_ns("2026-03-05T00:00"), _ns("2026-03-06T00:00"))])
    return write_series_csv(tmp_path / "midspan.csv", t, v, utc_offset_h=9)


def test_import_and_crossvalidate(processed_copy, camera_csv, tmp_path, capsys):
    assert main(["camera", "import", str(processed_copy), str(camera_csv)]) == 0
    out = capsys.readouterr().out
    assert "imported camera series 'midspan' for M3" in out and "1 gap(s)" in out
    assert "times: with their UTC offsets" in out
    assert (processed_copy / "camera").is_dir()
    stored = list((processed_copy / "camera").iterdir())
    assert len(stored) == 1 and stored[0].read_bytes() == camera_csv.read_bytes()
    assert not (stored[0].stat().st_mode & 0o222)  # read-only copy
    out_dir = tmp_path / "cv"
    capsys.readouterr()
    assert main(["crossval", str(processed_copy), "--out", str(out_dir)]) == 0
    assert "only 3 pairs: too few for statistics (5 needed)" in capsys.readouterr().out
    res = json.loads((out_dir / "crossval.json").read_text())
    for key in ("n_pairs", "bias_mm", "rmse_mm", "correlation", "pairs"):
        assert key in res
    assert res["n_pairs"] == 3 and res["reflector"] == "M3"
    assert res["offset_mm"] == pytest.approx(-12.0, abs=0.5)
    # three pairs are too few for statistics (issue 29): none is given, and the note says why
    assert res["rmse_mm"] is None and res["correlation"] is None and res["within_2sigma"] is None
    assert "too few for statistics" in res["note"]
    assert [p["epoch"] for p in res["pairs"]] == ["2026-03-02", "2026-03-09", "2026-03-16"]
    for name in ("overlay.png", "difference.png", "scatter.png", "crossval.csv"):
        assert (out_dir / name).stat().st_size > 1000 or name.endswith(".csv")
    # aligned at the second visit: that pair's difference is zero by construction
    capsys.readouterr()
    assert main(["crossval", str(processed_copy), "--out", str(out_dir), "--align-at", "2026-03-09", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["alignment"]["epoch"] == "2026-03-09" and abs(res["pairs"][1]["difference_mm"]) < 1e-9
    with Campaign.open(processed_copy, writable=False) as c:
        from projects.series.camera import crossval_summaries

        assert crossval_summaries(c)[0]["alignment"]["method"] == "at-date"
    assert main(["camera", "list", str(processed_copy)]) == 0
    assert "midspan" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["camera", "import", "{camp}", "{tmp}/missing.csv"], "no such file"),
    (["camera", "import", "{camp}", "{tmp}/garbage.csv"], "no header"),
    (["camera", "import", "{camp}", "{csv}", "--reflector", "R1"], "reference target"),
    (["camera", "import", "{camp}", "{csv}", "--reflector", "X9"], "unknown reflector"),
    (["camera", "import", "{camp}", "{csv}", "--timezone", "Mars/Olympus"], "time zone"),
    (["crossval", "{camp}", "--out", "{tmp}/o"], "no camera series yet"),
])
def test_bad_imports_leave_the_campaign_unchanged(processed_copy, camera_csv, tmp_path, capsys, argv, message):
    (tmp_path / "garbage.csv").write_text("1,2\n3,4\n")
    before = snapshot(processed_copy)
    args = [a.format(camp=processed_copy, tmp=tmp_path, csv=camera_csv) for a in argv]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert snapshot(processed_copy) == before


def test_duplicate_import_and_bad_crossval_arguments(processed_copy, camera_csv, tmp_path, capsys):
    assert main(["camera", "import", str(processed_copy), str(camera_csv)]) == 0
    before = snapshot(processed_copy)
    for argv, message in (
        (["camera", "import", str(processed_copy), str(camera_csv), "--name", "again"], "already in the campaign"),
        (["camera", "import", str(processed_copy), str(camera_csv)], "already in the campaign"),
        (["crossval", str(processed_copy), "--out", str(tmp_path / "o"), "--align-at", "yesterday"], "not ISO 8601"),
        (["crossval", str(processed_copy), "--out", str(tmp_path / "o"), "--window-min", "-5"], "positive"),
        (["crossval", str(processed_copy), "--out", str(tmp_path / "o"), "--series", "nope"], "no camera series"),
    ):
        capsys.readouterr()
        assert main(argv) == 1, argv
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1
        assert snapshot(processed_copy) == before

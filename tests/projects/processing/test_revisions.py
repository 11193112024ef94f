"""The state shown is the state (issue 38.6): what processing will recompute shows as stale before it runs, and a
stored value that processing changes is listed as a revision (visit, target, old → new, why)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli.main import main
from lidar.displacement_result import Displacement, EpochDisplacements
from lidar.stage2 import INPUT_PARTS, revisions, stale_parts


def _status(campaign, capsys) -> dict:
    assert main(["status", str(campaign), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _result(values: dict) -> EpochDisplacements:
    ds = [Displacement(rid, np.nan if d is None else d, np.nan if s is None else s, 0.0, 0.0, tuple(f))
          for rid, (d, s, f) in values.items()]
    return EpochDisplacements(tuple(ds), ("R1",), (), np.array([0.0, 0.0, 1.0]), np.zeros(3), "baseline")


def test_revisions_are_changes_beyond_half_a_sigma_or_of_severity():
    stored = {"M1": (-0.00210, 0.0001, ()), "M2": (-0.00300, 0.0001, ()), "M3": (-0.0010, 0.0001, ()),
              "M4": (None, None, ("missing",)), "M5": (-0.0020, 0.0001, ())}
    new = _result({"M1": (-0.00212, 0.0001, ()),  # 0.2 sigma: no revision
                   "M2": (-0.00360, 0.0001, ()),  # 6 sigma
                   "M3": (-0.0010, 0.0001, ("second_bright_object",)),  # a warning appears
                   "M4": (-0.0020, 0.0001, ()),  # a value appears
                   "M5": (-0.0020, 0.0001, ("grazing: the disc is 60 % of the beam's width",))})  # info only
    got = {r.target: r for r in revisions("v2", stored, new, "the baseline changed")}
    assert sorted(got) == ["M2", "M3", "M4"]
    assert got["M2"].line() == "v2 M2: -3.00 ± 0.10 mm → -3.60 ± 0.10 mm (the baseline changed)"
    assert got["M3"].new == "-1.00 ± 0.10 mm (warning: second bright object beside the target)"
    assert got["M4"].old == "no value (warning: no value (target not found))"


def test_stale_parts_name_what_changed():
    assert stale_parts({"air": "a", "settings": "s"}, {"air": "a", "settings": "t"}) == [INPUT_PARTS["settings"]]
    assert stale_parts({}, {"air": "a"}) == []  # nothing recorded: nothing claimed


@pytest.mark.slow
def test_an_air_series_and_a_new_baseline_show_stale_before_processing_and_revisions_after(
        processed_copy, tmp_path, capsys):
    labels = [e["epoch"] for e in _status(processed_copy, capsys)["epochs"]]
    assert not any(e["stale"] for e in _status(processed_copy, capsys)["epochs"])
    rows = ["time,temperature_c"] + [f"2026-03-{d:02d} {h:02d}:00,{8 + h / 4:.2f}" for d in range(1, 20)
                                     for h in range(24)]
    (tmp_path / "air.csv").write_text("\n".join(rows) + "\n")
    assert main(["env", "import", str(processed_copy), str(tmp_path / "air.csv"), "--kind", "temperature"]) == 0
    capsys.readouterr()
    stale = {e["epoch"]: e["stale"] for e in _status(processed_copy, capsys)["epochs"]}
    assert all("air series" in stale[lab] for lab in labels), stale  # seen before 'process' runs
    assert main(["process", str(processed_copy)]) == 0
    capsys.readouterr()
    assert not any(e["stale"] for e in _status(processed_copy, capsys)["epochs"])
    assert main(["settings", str(processed_copy), "baseline", labels[1]]) == 0
    capsys.readouterr()
    stale = {e["epoch"]: e["stale"] for e in _status(processed_copy, capsys)["epochs"]}
    assert all(stale[lab] == "the baseline changed" for lab in labels), stale
    assert main(["process", str(processed_copy)]) == 0
    capsys.readouterr()
    data = _status(processed_copy, capsys)
    revised = data["revisions"]["revised"]
    assert revised and {r["why"] for r in revised} == {"the baseline changed"}
    assert main(["status", str(processed_copy)]) == 0
    out = capsys.readouterr().out
    assert "value(s)" in out and "(the baseline changed)" in out
    assert len([ln for ln in out.splitlines() if ln.endswith("(the baseline changed)")]) <= 3  # --verbose: all

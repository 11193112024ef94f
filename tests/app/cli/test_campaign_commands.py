"""The campaign command line end to end on simulated visits, including every kind of bad input."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest

from app.cli.main import main
from projects.store.campaign import Campaign
from tests.app.cli.conftest import error_lines
from tests.projects.campaign_helpers import snapshot

DATES = ("2026-03-02T09:00", "2026-03-09T10:00", "2026-03-16T08:30")


def add_visit(camp: Path, field: Path, k: int, capsys) -> str:
    from lidar.plan import ScanPlan
    from lidar.simulate.files import simulate_fine

    label = DATES[k][:10]
    assert main(["add-epoch", str(camp), "--date", DATES[k], "--coarse", str(field / f"v{k}" / "coarse.laz")]) == 0
    plan_path = field / f"v{k}" / "plan.json"
    assert main(["plan", str(camp), "--epoch", label, "--out", str(plan_path)]) == 0
    if not (field / f"v{k}" / "fine.laz").exists():
        simulate_fine(field / f"v{k}", ScanPlan.load(plan_path).rois)
    assert main(["add-fine", str(camp), "--epoch", label, str(field / f"v{k}" / "fine.laz")]) == 0
    capsys.readouterr()
    return label


@pytest.fixture
def campaign(field_copy, tmp_path, capsys):
    camp = tmp_path / "camp"
    assert main(["init", str(camp), "--name", "Test bridge", "--layout", str(field_copy / "layout.csv"),
                 "--span-m", "40"]) == 0
    capsys.readouterr()
    return camp


def test_whole_flow_gives_true_displacements(campaign, field_copy, capsys):
    for k in range(3):
        add_visit(campaign, field_copy, k, capsys)
    assert main(["process", str(campaign)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert [ln.split()[:2] for ln in out[1:4]] == [[d[:10], "measured"] for d in DATES]  # one line per epoch computed
    assert out[-1].startswith("3 epoch(s): 3 measured; baseline 2026-03-02") and len(out) == 5
    assert main(["displacements", str(campaign), "--format", "csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert {"epoch", "datetime", "reflector", "displacement_mm", "sigma_mm", "flags", "epoch_state"} <= set(rows[0])
    assert {r["epoch_state"] for r in rows} <= {"processed", "warning"}
    assert len(rows) == 3 * 5
    truth = {k: json.loads((field_copy / f"v{k}" / "truth.json").read_text()) for k in range(3)}
    for r in rows:
        k = [d[:10] for d in DATES].index(r["epoch"])
        t = {x["id"]: x["vertical_displacement_m"] for x in truth[k]["targets"]}
        t0 = {x["id"]: x["vertical_displacement_m"] for x in truth[0]["targets"]}
        true_mm = (t[r["reflector"]] - t0[r["reflector"]]) * 1000
        assert abs(float(r["displacement_mm"]) - true_mm) < max(0.35, 4 * float(r["sigma_mm"] or 0)), r
    # incremental: nothing to do the second time, identical numbers, one line to say so
    before = snapshot(campaign)
    assert main(["process", str(campaign)]) == 0
    assert capsys.readouterr().out == "nothing to do: 3 epoch(s): 3 up to date; baseline 2026-03-02\n"
    assert main(["process", str(campaign), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert all(e["action"] == "up-to-date" for e in out["epochs"]) and out["displacements_updated"] == []
    after = snapshot(campaign)
    strip = lambda s: {k: v for k, v in s.items() if not k.endswith(".sqlite")}
    assert strip(before) == strip(after)
    with Campaign.open(campaign, writable=False) as c:
        assert c.integrity_check() == "ok"


def test_limits_status_and_export(campaign, field_copy, capsys, tmp_path):
    for k in range(2):
        add_visit(campaign, field_copy, k, capsys)
    assert main(["limit", str(campaign), "--rule", "abs:3,5"]) == 0
    assert main(["process", str(campaign)]) == 0
    capsys.readouterr()
    assert main(["status", str(campaign), "--json"]) == 0
    status = json.loads(capsys.readouterr().out)
    states = {t["reflector"]: t["state"] for t in status["targets"]}
    assert states["M3"] == "warning" and states["M1"] == "ok"  # -4 mm and -2.4 mm against 3 and 5 mm
    assert main(["export", str(campaign), "--out", str(tmp_path / "all.xlsx")]) == 0
    from openpyxl import load_workbook

    wb = load_workbook(tmp_path / "all.xlsx")
    assert {"epochs", "reflectors", "centroids", "displacements", "files", "log"} <= set(wb.sheetnames)


def test_bad_inputs_leave_the_campaign_unchanged(campaign, field_copy, capsys, tmp_path):
    add_visit(campaign, field_copy, 0, capsys)
    before = snapshot(campaign)
    truncated = tmp_path / "cut.laz"
    blob = (field_copy / "v1" / "coarse.laz").read_bytes()
    truncated.write_bytes(blob[: len(blob) // 3])
    cases = [
        (["add-epoch", str(campaign), "--date", "2026-04-01", "--coarse", str(truncated)], "cut.laz"),
        (["add-epoch", str(campaign), "--date", "2026-04-01", "--coarse", str(tmp_path / "none.laz")], "no such file"),
        (["add-epoch", str(campaign), "--date", "yesterday", "--coarse", str(field_copy / "v1" / "coarse.laz")],
         "not ISO 8601"),
        (["add-epoch", str(campaign), "--date", "2027-02-30", "--coarse", str(field_copy / "v1" / "coarse.laz")],
         "'2027-02-30' is an impossible date"),
        (["add-epoch", str(campaign), "--date", "2026-04-01", "--coarse", str(field_copy / "v1")],
         "is a folder, not a file"),
        (["add-epoch", str(campaign), "--date", "2026-04-01", "--coarse", str(field_copy / "v0" / "coarse.laz")],
         "already in the campaign"),
        (["add-epoch", str(campaign), "--date", DATES[0], "--coarse", str(field_copy / "v1" / "coarse.laz")],
         "already exists"),
        (["add-fine", str(campaign), "--epoch", "1999-01-01", str(field_copy / "v1" / "coarse.laz")], "no epoch"),
        (["process", str(campaign), "--epoch", "nope"], "no epoch 'nope'"),
        (["reflector", "retire", str(campaign), "Q7", "--date", "2026-05-01"], "unknown reflector 'Q7'"),
        (["limit", str(campaign), "--rule", "banana"], "not understood"),
        (["export", str(campaign), "--out", str(tmp_path / "x.doc")], "give a name ending in .xlsx or .csv"),
        (["export", str(campaign), "--out", str(tmp_path / "nope" / "x.xlsx")], "does not exist"),
        (["plan", str(campaign), "--epoch", DATES[0][:10], "--out", str(tmp_path / "nope" / "p.json")],
         "does not exist"),
        (["process", str(tmp_path / "nowhere")], "no campaign here"),
    ]
    for argv, message in cases:
        code = main(argv)
        err = capsys.readouterr().err.strip()
        assert code == 1, argv
        assert message in err and len(error_lines(err)) == 1, (argv, err)
        assert snapshot(campaign) == before, argv
    bad_layout = tmp_path / "layout.csv"
    bad_layout.write_text("id,group,x,y\nR1,reference,0,0\n")
    assert main(["init", str(tmp_path / "c2"), "--name", "x", "--layout", str(bad_layout)]) == 1
    assert "missing column(s) z" in capsys.readouterr().err
    assert not (tmp_path / "c2").exists()


def test_reflector_life_cycle(campaign, capsys):
    assert main(["reflector", "add", str(campaign), "M6", "--group", "measurement", "--xyz", "20,0,7",
                 "--installed", "2026-06-01"]) == 0
    assert main(["reflector", "replace", str(campaign), "M2", "M2b", "--date", "2026-07-01"]) == 0
    assert main(["reflector", "list", str(campaign), "--json"]) == 0
    rows = {r["id"]: r for r in json.loads(capsys.readouterr().out.split("\n", 2)[-1])}
    assert rows["M2"]["retired"].startswith("2026-07-01") and rows["M2b"]["replaces"] == "M2"
    with Campaign.open(campaign, writable=False) as c:
        assert "M2" in c.layout("2026-06-15T00:00:00+00:00").ids
        ids = c.layout("2026-07-15T00:00:00+00:00").ids
        assert "M2b" in ids and "M2" not in ids and "M6" in ids


def test_changing_a_parameter_recomputes_exactly_what_it_affects(campaign, field_copy, capsys):
    for k in range(2):
        add_visit(campaign, field_copy, k, capsys)
    assert main(["process", str(campaign)]) == 0
    capsys.readouterr()
    # a displacement parameter: no centroid is recomputed, every displacement set is
    assert main(["settings", str(campaign), "normal_mode", "epoch"]) == 0
    assert main(["process", str(campaign), "--json"]) == 0
    out = json.loads(capsys.readouterr().out.split("\n", 1)[1])
    assert [e["action"] for e in out["epochs"]] == ["displacements", "displacements"]  # centroids not recomputed
    assert len(out["displacements_updated"]) == 2
    # a measurement parameter: every epoch is re-measured
    assert main(["settings", str(campaign), "min_points", "800"]) == 0
    assert main(["process", str(campaign), "--json"]) == 0
    out = json.loads(capsys.readouterr().out.split("\n", 1)[1])
    assert [e["action"] for e in out["epochs"]] == ["measured", "measured"]
    assert main(["settings", str(campaign), "min_points", "five"]) == 1
    assert "not a valid value" in capsys.readouterr().err


@pytest.mark.slow
def test_an_epoch_measured_by_check_is_measured_then_processed_never_up_to_date(campaign, field_copy, capsys):
    for k in range(2):
        add_visit(campaign, field_copy, k, capsys)
    assert main(["process", str(campaign)]) == 0
    label = add_visit(campaign, field_copy, 2, capsys)
    assert main(["check", str(campaign), "--epoch", label]) in (0, 3)
    capsys.readouterr()
    assert main(["status", str(campaign), "--json"]) == 0
    state = {e["epoch"]: e for e in json.loads(capsys.readouterr().out)["epochs"]}[label]
    # its centroids are kept (nothing of stage 1 is stale); its displacements are what processing will add
    assert state["state"] == "measured" and state["stale"] == "displacements not computed yet"
    assert main(["process", str(campaign)]) == 0
    lines = capsys.readouterr().out.splitlines()
    mine = [ln for ln in lines if ln.startswith(label)]
    assert len(mine) == 1 and mine[0].split()[1] == "processed" and "check" in mine[0]
    # the two earlier epochs are either untouched or recomputed because the new epoch refined the
    # campaign-wide field model, and then the line says so (never "parameters changed")
    others = [ln for ln in lines if ln.split()[:1] and ln.split()[0] in state_labels(campaign) and ln.split()[0] != label]
    for ln in others:  # an up-to-date epoch has no line of its own
        assert "displacements" in ln and "field model" in ln, ln
    assert lines[-1].startswith("3 epoch(s): 1 processed, 2 up to date" if not others else
                                f"3 epoch(s): 1 processed, {len(others)} with displacements recomputed"), lines


def state_labels(campaign) -> set:
    with Campaign.open(campaign, writable=False) as c:
        return {e.label for e in c.epochs()}


def test_status_lists_the_last_epochs_and_says_so(processed_copy, capsys, monkeypatch):
    import app.cli.commands_campaign as cc

    monkeypatch.setattr(cc, "STATUS_EPOCHS", 2)
    assert main(["status", str(processed_copy)]) == 0
    out = capsys.readouterr().out
    assert "(last 2 of 3 epochs; --all for every epoch)" in out and "\n2026-03-02 " not in out
    assert main(["status", str(processed_copy), "--all"]) == 0
    out = capsys.readouterr().out
    assert all(f"\n{d[:10]} " in out for d in DATES) and "--all for every epoch" not in out


def test_status_shows_each_epochs_range_scale(processed_copy, capsys):
    import re

    assert main(["status", str(processed_copy), "--all"]) == 0
    out = capsys.readouterr().out
    assert "scale" in out.splitlines()[1]  # the table's header
    assert "0 (baseline)" in out
    assert len(re.findall(r"[+-]\d+\.\d±\d+\.\d ppm", out)) == 2  # the two later epochs, each with its sigma
    # the campaign's instrument as the field model found it: its range walk and axis errors
    line = next(ln for ln in out.splitlines() if ln.startswith("instrument (the campaign's field model): "))
    assert "range walk: " in line and "axis errors: " in line
    assert main(["status", str(processed_copy), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    epochs = data["epochs"]
    assert all(isinstance(e["scale_ppm"], float) and e["scale_sigma_ppm"] >= 0 for e in epochs)
    assert set(data["instrument"]) == {"range_walk", "range_walk_determined", "axis_errors", "sigma0"}
    assert all(set(a) == {"axis", "arcsec", "sigma_arcsec"} for a in data["instrument"]["axis_errors"])

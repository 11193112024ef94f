"""No silent empty epoch, flags by severity and an explicit baseline (issue 17, points 2, 5 and 6)."""
from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from app.cli.main import main
from lidar.simulate import EpochConditions, ScannerSetup
from lidar.simulate.files import load_scene, save_scene, simulate_coarse, simulate_fine
from projects.processing.stages import plan_epoch
from projects.results.state import epoch_state
from projects.results.status import campaign_status
from projects.store.campaign import Campaign
from tests.projects.conftest import MODEL

DECK = tuple(t.id for t in MODEL.targets if t.group == "measurement")


def _visit(field, name, date, camp, conditions, seed, fine_conditions=None):
    folder = field / name
    simulate_coarse(folder, setup=ScannerSetup((22.0, -13.0, 1.5), heading_deg=120.0), conditions=conditions,
                    model=MODEL, seed=seed, coarse_step_deg=0.06)
    assert main(["add-epoch", str(camp), "--date", date, "--coarse", str(folder / "coarse.laz")]) == 0
    with Campaign.open(camp) as c:
        plan = plan_epoch(c, date[:10])
    if fine_conditions is not None:  # something changed between the coarse and the fine scans
        setup, _, seed_, step = load_scene(folder)
        save_scene(folder, setup, fine_conditions, seed_, step)
    fine, _ = simulate_fine(folder, plan.rois, model=MODEL, name="fine.laz")
    assert main(["add-fine", str(camp), "--epoch", date[:10], str(fine)]) == 0


@pytest.mark.slow
def test_an_epoch_without_deck_targets_is_a_problem_not_a_silent_gap(processed_copy, field_copy, capsys):
    # the deck targets were seen in the coarse scan, then hidden (e.g. a parked vehicle) for the fine scans
    _visit(field_copy, "gone", "2026-03-23T09:00", processed_copy, EpochConditions(), seed=77,
           fine_conditions=EpochConditions(occluded=DECK))
    capsys.readouterr()
    assert main(["process", str(processed_copy)]) == 3  # processed, but no trustworthy result
    err = capsys.readouterr().err
    assert "2026-03-23" in err and "deck_not_measured" in err
    with Campaign.open(processed_copy, writable=False) as c:
        state, flags = epoch_state(c, "2026-03-23")
        assert state == "problem"
        assert any(f.startswith("deck_not_measured") for f in flags)
        status = campaign_status(c)
        others = [e for e in status["epochs"] if e["epoch"] != "2026-03-23"]
        assert all(e["state"] in ("processed", "warning") for e in others)  # the rest is not red
    assert main(["status", str(processed_copy)]) == 0
    out = capsys.readouterr().out
    assert "PROBLEM in 2026-03-23" in out and "epochs with problems: 1" in out
    assert main(["displacements", str(processed_copy), "--format", "json"]) == 0
    rows = [r for r in json.loads(capsys.readouterr().out) if r["epoch"] == "2026-03-23"]
    assert rows and all(r["displacement_mm"] is None and r["severity"] == "problem" for r in rows)
    pdf = processed_copy.parent / "problem.pdf"
    assert main(["report", str(processed_copy), "--out", str(pdf)]) == 0
    if shutil.which("pdftotext"):
        text = subprocess.run(["pdftotext", str(pdf), "-"], capture_output=True, text=True, check=True).stdout
        assert "Epochs without a trustworthy result" in text and "PROBLEM" in text
        assert "too few deck targets measured" in text and "deck_not_measured" not in text  # words in the body
        assert "Visits that need attention" in text


@pytest.mark.slow
def test_an_epoch_dated_before_the_baseline_gets_negative_time_not_a_new_baseline(processed_copy, field_copy,
                                                                                     capsys):
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.settings().get("baseline") == "2026-03-02"  # stored once, at the first processing
        before = {(r.epoch, r.reflector): r.displacement_m for r in c.displacements()}
    _visit(field_copy, "early", "2026-02-23T09:00", processed_copy, EpochConditions(midspan_displacement_m=0.002),
           seed=78)
    assert main(["process", str(processed_copy)]) == 0
    capsys.readouterr()
    assert main(["displacements", str(processed_copy), "--format", "json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["baseline"] for r in rows} == {"2026-03-02"}
    early = [r for r in rows if r["epoch"] == "2026-02-23"]
    assert early and all(r["days_from_baseline"] == pytest.approx(-7.0) for r in early)
    mid = [r for r in early if r["reflector"] == "M3"]
    assert mid and mid[0]["displacement_mm"] == pytest.approx(2.0, abs=0.5)  # 2 mm up, against the baseline
    with Campaign.open(processed_copy, writable=False) as c:
        after = {(r.epoch, r.reflector): r.displacement_m for r in c.displacements()}
    # nothing else was re-referenced (that would move them by the early epoch's 2 mm); the campaign's field
    # model, re-fitted with one more visit, may move them within their sigma
    assert all(abs(after[k] - before[k]) < 0.3e-3 for k in before)
    assert main(["settings", str(processed_copy), "baseline", "2026-03-09"]) == 0
    assert "re-referenced" in capsys.readouterr().err
    with Campaign.open(processed_copy, writable=False) as c:
        assert any(r.action == "setting" and "2026-03-09" in str(r.details) for r in c.log())


def test_identification_settings_are_validated(processed_copy, capsys):
    assert main(["settings", str(processed_copy), "levelled", "false"]) == 0
    assert main(["settings", str(processed_copy), "layout_up", "0,1,0"]) == 0
    assert main(["settings", str(processed_copy), "max_tilt_deg", "1.5"]) == 0
    assert main(["settings", str(processed_copy), "max_tilt_deg", "auto"]) == 0  # back to the scanner profile's
    for key, bad in (("levelled", "maybe"), ("layout_up", "0,0"), ("layout_up", "0,0,0"), ("normal_mode", "up"),
                     ("max_tilt_deg", "-1")):
        assert main(["settings", str(processed_copy), key, bad]) == 1
        assert key in capsys.readouterr().err
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.settings()["levelled"] is False and c.settings()["layout_up"] == "0,1,0"
        assert c.settings()["max_tilt_deg"] is None
        from projects.processing.stages import max_tilt, parameters

        assert max_tilt(c, parameters(c)) is None  # not levelled: no limit
        assert max_tilt(c, {**parameters(c), "levelled": True}) == c.profile.max_tilt_deg == 2.0


def test_status_names_the_suspects_of_an_ambiguous_pier_move(processed_copy, capsys):
    import numpy as np

    from lidar.displacement import Displacement, EpochDisplacements, ReferenceCheck

    checks = (ReferenceCheck("R1", 0.003, 0.003, False, False, True), ReferenceCheck("R2", 0.003, 0.003, False, False, True),
              ReferenceCheck("R3", 0.0, 0.0, False, False), ReferenceCheck("R4", 0.0, 0.0, False, False))
    res = EpochDisplacements((Displacement("M1", -0.001, 0.0002, 1.0, 1.001),), ("R3", "R4"), checks,
                             np.array([0, 0, 1.0]), np.zeros(3), "auto", ("reference_change_ambiguous",))
    with Campaign.open(processed_copy) as c:
        c.save_displacements("2026-03-16", "2026-03-02", res, "test")
        state, flags = epoch_state(c, "2026-03-16")
    assert state == "warning"
    assert any("R1 or R2 moved" in f for f in flags)
    assert main(["status", str(processed_copy)]) == 0
    assert "R1 or R2 moved" in capsys.readouterr().out


def _flag_centroid(c, label, rid, flag):
    from dataclasses import replace

    cents = c.centroids(label)
    cents[rid] = replace(cents[rid], flags=tuple(cents[rid].flags) + (flag,))
    c.save_centroids(label, cents, c.result(label).inputs_hash, {})  # same inputs: nothing becomes stale


def test_centroid_flags_decide_the_state_everywhere_reference_targets_included(processed_copy, capsys):
    import csv
    import io

    from common.flags import FLAG_CLIPPED, FLAG_SECOND_OBJECT

    with Campaign.open(processed_copy) as c:
        assert {s for s, _ in (epoch_state(c, e.label) for e in c.epochs())} <= {"processed"}
        _flag_centroid(c, "2026-03-09", "R1", FLAG_SECOND_OBJECT)  # the demo's cable-tie week: a pier target
        _flag_centroid(c, "2026-03-16", "M2", FLAG_CLIPPED)   # a deck target touching its window's edge
        state, flags = epoch_state(c, "2026-03-09")
        assert state == "warning" and "second_bright_object: R1" in flags
        state, flags = epoch_state(c, "2026-03-16")
        assert state == "warning" and "clipped_by_window: M2" in flags
        assert epoch_state(c, "2026-03-02")[0] == "processed"
        status = {e["epoch"]: e for e in campaign_status(c)["epochs"]}
        assert status["2026-03-09"]["state"] == status["2026-03-16"]["state"] == "warning"
    assert main(["process", str(processed_copy)]) == 0  # nothing was made stale by the edit
    capsys.readouterr()
    assert main(["status", str(processed_copy)]) == 0
    out = capsys.readouterr().out
    assert "epochs with problems: 0, with warnings: 2" in out
    assert "WARNING in 2026-03-09: second bright object beside the target: R1" in out  # in words, one line
    assert "WARNING in 2026-03-16: target clipped by its window: M2" in out
    assert "  action: re-scan the target with a larger window" in out  # what to do, below it
    assert all(len(line) <= 120 for line in out.splitlines() if line.startswith("2026-"))
    assert main(["displacements", str(processed_copy)]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert {r["epoch"]: r["epoch_state"] for r in rows} == {"2026-03-02": "processed", "2026-03-09": "warning",
                                                           "2026-03-16": "warning"}
    assert all(r["state"] in ("ok", "warning", "alarm", "unknown") for r in rows)  # the limit state stays


def test_decide_state_uses_every_flag():
    import doctest

    import projects.results.state
    from projects.results.state import decide_state

    assert doctest.testmod(projects.results.state).failed == 0

    assert decide_state("processed", []) == "processed"
    assert decide_state("processed", ["saturated: R2", "normal_refitted_in_epoch"]) == "processed"
    assert decide_state("processed", ["saturated: R2", "few_points: M1"]) == "processed"  # sigma carries both
    assert decide_state("processed", ["saturated: R2", "clipped_by_window: M1"]) == "warning"
    assert decide_state("processed", ["few_points: M1", "reference_inconsistent"]) == "problem"
    for stage in ("imported", "planned", "scanned", "measured"):
        assert decide_state(stage, ["reference_inconsistent"]) == stage
    with pytest.raises(ValueError):
        decide_state("done", [])

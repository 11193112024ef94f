"""Visits of several set-ups and scans in a project frame, through the command line as a surveyor types it."""
from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from app.cli.main import main
from common.flags import FLAG_SETUP_NOT_JOINED, code
from lidar.layout import layout_from_model, write_layout_csv
from lidar.plan import ScanPlan
from lidar.simulate import BridgeModel, EpochConditions, ScannerSetup
from lidar.simulate.files import simulate_coarse, simulate_fine
from lidar.simulate.visits import export_registered, project_transform
from projects.outputs.report import ReportScope, gather
from projects.outputs.report.flowables import styles
from projects.outputs.report.pdf import plan_table
from projects.store.campaign import Campaign
from tests.projects.campaign_helpers import snapshot

MODEL = BridgeModel()
DATES = ("2026-03-02T09:00", "2026-03-09T10:00")
#: Two visits of the 40 m bridge, each from two stations (one beside each half of the span).
STATIONS = (
    (ScannerSetup((8.0, -11.0, 1.5), heading_deg=40.0), ScannerSetup((32.0, -12.0, 1.5), heading_deg=220.0)),
    (ScannerSetup((10.0, -13.0, 1.4), heading_deg=130.0), ScannerSetup((30.0, -10.0, 1.6), heading_deg=300.0)),
)
CONDITIONS = (EpochConditions(), EpochConditions(midspan_displacement_m=-0.004))


@pytest.fixture(scope="module")
def two_setups(tmp_path_factory) -> Path:
    """Coarse scans of two visits of two set-ups each (fine scans are simulated from each set-up's plan)."""
    root = tmp_path_factory.mktemp("setups")
    write_layout_csv(layout_from_model(MODEL, noise_m=0.02, rng=np.random.default_rng(2)), root / "layout.csv")
    for k, (stations, cond) in enumerate(zip(STATIONS, CONDITIONS, strict=False)):
        for s, setup in enumerate(stations, start=1):
            simulate_coarse(root / f"v{k}" / f"setup{s}", setup=setup, conditions=cond, model=MODEL,
                            seed=40 + 10 * k + s, coarse_step_deg=0.06)
    return root


def _init(camp: Path, field: Path, capsys) -> Path:
    assert main(["init", str(camp), "--name", "Two stations", "--layout", str(field / "layout.csv"),
                 "--span-m", "40"]) == 0
    capsys.readouterr()
    return camp


def _fine(folder: Path, plan: Path, *, keep: int = 0) -> Path:
    rois = ScanPlan.load(plan).rois
    fine, _ = simulate_fine(folder, rois[:keep] if keep else rois, model=MODEL, name="fine.laz")
    return fine


def _visit(camp: Path, field: Path, k: int, capsys, *, keep_second: int = 0) -> str:
    label = DATES[k][:10]
    v = field / f"v{k}"
    assert main(["add-epoch", str(camp), "--date", DATES[k], "--coarse", str(v / "setup1" / "coarse.laz")]) == 0
    assert main(["add-setup", str(camp), "--epoch", label, "--coarse", str(v / "setup2" / "coarse.laz")]) == 0
    assert "added set-up 2 to epoch" in capsys.readouterr().out
    for s in (1, 2):
        plan = v / f"setup{s}" / "plan.json"
        assert main(["plan", str(camp), "--epoch", label, "--setup", str(s), "--out", str(plan)]) == 0
        assert f"(set-up {s})" in capsys.readouterr().out
        fine = _fine(v / f"setup{s}", plan, keep=keep_second if s == 2 else 0)
        # the last set-up added is the default: set-up 1's fine scans name it
        assert main(["add-fine", str(camp), "--epoch", label, *(["--setup", "1"] if s == 1 else []), str(fine)]) == 0
        assert f"set-up {s}" in capsys.readouterr().out
    return label


@pytest.fixture
def stations(two_setups, tmp_path) -> Path:
    dst = tmp_path / "stations"
    shutil.copytree(two_setups, dst, symlinks=True)
    return dst


def test_two_set_ups_a_visit_are_planned_measured_and_joined(stations, tmp_path, capsys):
    field = stations
    camp = _init(tmp_path / "camp", field, capsys)
    # both coarse scans first, then the fine scans: the visit can be planned as a whole
    assert main(["settings", str(camp), "plan_together", "true"]) == 0
    for k in range(2):
        _visit(camp, field, k, capsys)
    assert main(["process", str(camp)]) == 0
    capsys.readouterr()
    assert main(["displacements", str(camp), "--format", "csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    truth = [json.loads((field / f"v{k}" / "setup1" / "truth.json").read_text()) for k in range(2)]
    t = [{x["id"]: x["vertical_displacement_m"] for x in tr["targets"]} for tr in truth]
    later = [r for r in rows if r["epoch"] == DATES[1][:10]]
    assert len(later) == 5 and all(r["displacement_mm"] for r in later)
    for r in later:
        err = float(r["displacement_mm"]) - (t[1][r["reflector"]] - t[0][r["reflector"]]) * 1e3
        assert abs(err) < max(0.3, 3 * float(r["sigma_mm"])), r
    with Campaign.open(camp, writable=False) as c:
        doc = c.systematics(DATES[1][:10])["setups"]
        assert doc["joined"] == [1, 2] and doc["motions"][0]["shared"] and doc["residuals"]
        assert set(doc["systematics"]) == {"2"}
        assert "2026-03-09#2" in c.field_model()[0].visits
    capsys.readouterr()
    assert main(["process", str(camp), "--json"]) == 0  # nothing to do the second time
    assert all(e["action"] == "up-to-date" for e in json.loads(capsys.readouterr().out)["epochs"])
    # the check and the field sheet of a set-up
    code_ = main(["check", str(camp), "--epoch", DATES[1][:10], "--setup", "2", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert doc["targets"] and doc["visit"]["setups"] == [1, 2]  # after the last set-up: the visit's one verdict
    assert code_ == (0 if doc["visit"]["ok"] else 3)
    assert main(["field-sheet", str(camp), "--epoch", DATES[1][:10], "--out", str(tmp_path / "s2.pdf")]) == 0
    assert (tmp_path / "s2.pdf").stat().st_size > 1000
    assert main(["check", str(camp), "--epoch", DATES[1][:10], "--setup", "3"]) == 1
    assert "no set-up 3; its set-ups are 1, 2" in capsys.readouterr().err
    # the report's plan tables: each set-up's windows, its closure marked
    with Campaign.open(camp, writable=False) as c:
        content = gather(c, ReportScope(), with_previews=False)
    e = content.epochs[-1]
    assert set(e.setup_plans) == {2}
    story = plan_table(e.setup_plans[2][0], e.setup_plans[2][1], styles(), setup=2)
    head = story[0].getPlainText()
    assert head.startswith("Set-up 2 (2. of the visit's 2, planned together)") and "closure:" in head
    rows = story[-1]._cellvalues
    assert rows[-1][0].getPlainText().endswith("(closure)")


def test_a_set_up_sharing_too_few_targets_is_a_problem_not_a_traceback(stations, tmp_path, capsys):
    field = stations
    camp = _init(tmp_path / "camp", field, capsys)
    _visit(camp, field, 0, capsys)
    _visit(camp, field, 1, capsys, keep_second=2)  # set-up 2 of the second visit scans two windows only
    assert main(["process", str(camp)]) == 3
    err = capsys.readouterr().err
    assert FLAG_SETUP_NOT_JOINED in err and "set-up 2" in err and "Traceback" not in err
    with Campaign.open(camp, writable=False) as c:
        ds = c.displacement_set(DATES[1][:10])
        (flag,) = [f for f in ds.flags if code(f) == FLAG_SETUP_NOT_JOINED]
        assert "well-spread" in flag


def test_a_registered_export_with_its_sop_gives_the_scanner_frame_displacements(processed, field_copy, tmp_path,
                                                                               capsys):
    """The same three visits as SOCS files (the processed campaign) and as exports in a project frame."""
    camp = _init(tmp_path / "camp", field_copy, capsys)
    rng = np.random.default_rng(11)
    with Campaign.open(processed, writable=False) as c:
        visits = [(e.label, e.datetime, c.path_of(c.files(e.label, "coarse")[0]), c.path_of(c.files(e.label, "fine")[0]))
                  for e in c.epochs()]
    for k, (label, when, coarse, fine) in enumerate(visits):
        src = tmp_path / f"socs{k}"
        src.mkdir()
        shutil.copyfile(coarse, src / "coarse.laz")
        shutil.copyfile(fine, src / "fine.laz")
        out = export_registered(src, tmp_path / f"exported{k}", project_transform(rng, tilt_deg=0.05))
        assert main(["add-epoch", str(camp), "--date", when, "--label", label, "--coarse", str(out["coarse.laz"]),
                     "--pose", str(out["sop"])]) == 0
        assert main(["add-fine", str(camp), "--epoch", label, str(out["fine.laz"])]) == 0  # the set-up's pose
    assert main(["process", str(camp)]) == 0
    with Campaign.open(processed, writable=False) as a, Campaign.open(camp, writable=False) as b:
        da = {(r.epoch, r.reflector): r for r in a.displacements()}
        db = {(r.epoch, r.reflector): r for r in b.displacements()}
        assert set(da) == set(db) and len(da) == 15
        for key, r in da.items():
            assert r.displacement_m is not None and db[key].displacement_m is not None
            assert abs(r.displacement_m - db[key].displacement_m) < 1e-5, key  # 0.01 mm
        f = b.files(visits[0][0], "coarse")[0]
        assert f.frame_for(1).carry and f.frame_for(1).source == "pose"


def test_a_project_frame_scan_without_a_pose_is_refused_in_one_line(processed_copy, tmp_path, capsys):
    rng = np.random.default_rng(5)
    with Campaign.open(processed_copy, writable=False) as c:
        e = c.epochs()[0]
        coarse = c.path_of(c.files(e.label, "coarse")[0])
    src = tmp_path / "socs"
    src.mkdir()
    shutil.copyfile(coarse, src / "coarse.laz")
    out = export_registered(src, tmp_path / "exported", project_transform(rng))
    before = snapshot(processed_copy)
    capsys.readouterr()
    assert main(["add-epoch", str(processed_copy), "--date", "2026-03-23", "--coarse", str(out["coarse.laz"])]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "project frame" in err and "--pose" in err and "--origin" in err
    assert str(out["coarse.laz"]) in err
    assert snapshot(processed_copy) == before
    bad = tmp_path / "bad.txt"
    bad.write_text("1 0 0 0\n0 1 0 0\n")
    for extra, says in ((["--pose", str(bad)], "4 rows of 4 numbers"),
                        (["--pose", str(out["sop"]), "--origin", "1,2,3"], "not both"),
                        (["--up", "0,0,1"], "--up goes with --origin"),
                        (["--origin", "1,2"], "three numbers")):
        assert main(["add-epoch", str(processed_copy), "--date", "2026-03-23", "--coarse", str(out["coarse.laz"]),
                     *extra]) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and says in err, err
    assert snapshot(processed_copy) == before
    # a fine scan in a project frame for a set-up whose pose is unknown: refused the same way
    label = e.label
    assert main(["add-fine", str(processed_copy), "--epoch", label, str(out["coarse.laz"])]) == 1
    assert "project frame" in capsys.readouterr().err
    assert snapshot(processed_copy) == before
    # with its scanner position only: accepted, carried into the project's axes at that position
    sop = np.loadtxt(out["sop"], comments="#")
    origin = ",".join(f"{v:.4f}" for v in sop[:3, 3])
    assert main(["add-epoch", str(processed_copy), "--date", "2026-03-23", "--coarse", str(out["coarse.laz"]),
                 "--origin", origin]) == 0
    assert main(["info", str(out["coarse.laz"])]) == 0
    assert "project frame" in capsys.readouterr().out


def test_plan_shows_the_visit_planned_together_and_each_set_up_keeps_its_share(stations, tmp_path, capsys):
    """Issue 40: 'plan --setup K' writes set-up K's plan within the visit's; 'plan' shows the whole visit in order."""
    field = stations
    camp = _init(tmp_path / "camp", field, capsys)
    assert main(["settings", str(camp), "plan_together", "true"]) == 0  # the default, said
    v = field / "v0"
    assert main(["add-epoch", str(camp), "--date", DATES[0], "--coarse", str(v / "setup1" / "coarse.laz")]) == 0
    assert main(["plan", str(camp), "--epoch", DATES[0][:10], "--out", str(tmp_path / "alone.json")]) == 0
    alone = json.loads((tmp_path / "alone.json").read_text())
    assert "visit" not in alone and "setup" not in alone  # one set-up: as before
    assert main(["add-setup", str(camp), "--epoch", DATES[0][:10], "--coarse", str(v / "setup2" / "coarse.laz")]) == 0
    capsys.readouterr()
    docs = {}
    for s in (1, 2):
        out = tmp_path / f"p{s}.json"
        assert main(["plan", str(camp), "--epoch", DATES[0][:10], "--setup", str(s), "--out", str(out)]) == 0
        text = capsys.readouterr().out
        assert "set-ups, planned together" in text and "1. set-up 1:" in text and "2. set-up 2:" in text
        docs[s] = json.loads(out.read_text())
        assert docs[s]["setup"] == s and docs[s]["visit"]["setups"] == [1, 2]
        ScanPlan.from_json(docs[s])  # the plan JSON contract
    assert docs[2]["visit"]["ties"]  # set-up 2 keeps the targets that join it to set-up 1
    windows = {s: {r["reflector"] for r in d["rois"] if not r.get("closure")} for s, d in docs.items()}
    assert all(any(r.get("closure") for r in d["rois"]) for d in docs.values())
    deck = {r["reflector"] for d in docs.values() for r in d["rois"] if r["group"] == "measurement"}
    twice = {t for t in deck if t in windows[1] and t in windows[2]}
    extra = set(docs[2]["visit"]["ties"]) | {t for d in docs.values() for t in d["visit"]["second_sightings"]}
    assert twice <= extra  # a deck target is scanned twice to join the set-ups, or in the time left
    budget = docs[1]["visit"]["visit_budget_seconds"]
    assert budget == pytest.approx(2 * 3600.0)  # budget_min (60) a set-up: the time the two would have alone
    assert docs[1]["budget_seconds"] + docs[2]["budget_seconds"] == pytest.approx(budget, rel=1e-3)
    # the visit's own time, when the surveyor gives it: the set-ups are planned again within it
    assert main(["settings", str(camp), "visit_budget_min", "45"]) == 0
    assert main(["plan", str(camp), "--epoch", DATES[0][:10], "--setup", "2", "--out", str(tmp_path / "v.json")]) == 0
    assert json.loads((tmp_path / "v.json").read_text())["visit"]["visit_budget_seconds"] == pytest.approx(2700.0)
    assert main(["settings", str(camp), "visit_budget_min", "auto"]) == 0
    # planned alone again, from the same scans
    assert main(["settings", str(camp), "plan_together", "false"]) == 0
    capsys.readouterr()
    assert main(["plan", str(camp), "--epoch", DATES[0][:10], "--setup", "2", "--out", str(tmp_path / "a2.json")]) == 0
    assert "each planned as if it were alone" in capsys.readouterr().out
    assert "visit" not in json.loads((tmp_path / "a2.json").read_text())


@pytest.mark.parametrize("together", [True, False])
def test_a_set_up_added_after_the_first_ones_fine_scans_leaves_its_plan_alone(stations, tmp_path, capsys, together):
    """The second station's coarse scan, taken after the first station's fine scans (the usual order on site), must
    not re-plan windows already scanned: planned together, set-up 1's plan is frozen and set-up 2 plans around it."""
    field = stations
    camp = _init(tmp_path / "camp", field, capsys)
    assert main(["settings", str(camp), "plan_together", str(together).lower()]) == 0
    v, label = field / "v0", DATES[0][:10]
    assert main(["add-epoch", str(camp), "--date", DATES[0], "--coarse", str(v / "setup1" / "coarse.laz")]) == 0
    plan = tmp_path / "p1.json"
    assert main(["plan", str(camp), "--epoch", label, "--out", str(plan)]) == 0
    assert main(["add-fine", str(camp), "--epoch", label, str(_fine(v / "setup1", plan))]) == 0
    assert main(["process", str(camp)]) == 0
    before = plan.read_text()
    assert main(["add-setup", str(camp), "--epoch", label, "--coarse", str(v / "setup2" / "coarse.laz")]) == 0
    assert main(["plan", str(camp), "--epoch", label, "--setup", "1", "--out", str(tmp_path / "again.json")]) == 0
    assert json.loads((tmp_path / "again.json").read_text())["rois"] == json.loads(before)["rois"]
    capsys.readouterr()
    assert main(["status", str(camp), "--json"]) == 0
    epoch = next(e for e in json.loads(capsys.readouterr().out)["epochs"] if e["epoch"] == label)
    assert "set-up 1" not in epoch["stale"] and not epoch["stale"].startswith("inputs"), epoch["stale"]
    # set-up 2's plan: within the visit's, around set-up 1's windows (as scanned), which join it
    p2 = tmp_path / "p2.json"
    assert main(["plan", str(camp), "--epoch", label, "--setup", "2", "--out", str(p2)]) == 0
    doc = json.loads(p2.read_text())
    if together:
        first = {r["reflector"] for r in json.loads(before)["rois"] if not r.get("closure")}
        ties = doc["visit"]["ties"]
        assert doc["visit"]["setups"] == [1, 2] and len(ties) >= 3 and set(ties) <= first
        # set-up 1 was planned as if it were alone (a budget of its own): set-up 2 gets what it left of the visit's
        # (budget_min a set-up)
        spent = min(ScanPlan.from_json(json.loads(before)).total_seconds, 3600.0)
        assert doc["visit"]["visit_budget_seconds"] == pytest.approx(7200.0)
        assert doc["budget_seconds"] == pytest.approx(7200.0 - spent, rel=1e-3)
    else:
        assert "visit" not in doc
    # its fine scans measured with that plan, the visit processes and joins
    assert main(["add-fine", str(camp), "--epoch", label, str(_fine(v / "setup2", p2))]) == 0
    assert main(["process", str(camp)]) == 0
    with Campaign.open(camp, writable=False) as c:
        assert c.plan(label, 1).to_json()["rois"] == json.loads(before)["rois"]
        assert c.systematics(label)["setups"]["joined"] == [1, 2]
    # the other way of planning, now that both set-ups are scanned: nothing is planned again
    assert main(["settings", str(camp), "plan_together", str(not together).lower()]) == 0
    capsys.readouterr()
    assert main(["process", str(camp), "--json"]) == 0
    assert all(e["action"] == "up-to-date" for e in json.loads(capsys.readouterr().out)["epochs"])

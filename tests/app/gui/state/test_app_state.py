"""The application's state, driven without Qt: what its subscribers hear as a surveyor works."""
from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

from app.gui import actions
from app.gui.state.app_state import AppState
from app.gui.state.cloud_display import POINT_BUDGET, budget_indices, change_scale
from app.gui.state.folders import LastFolders
from app.gui.state.next_step import next_step
from app.gui.state.status import StatusLine
from app.gui.state.words import in_app_words
from projects.store.campaign import Campaign
from tests.projects.campaign_helpers import snapshot


class Recorder:
    """Everything an AppState emitted, in order: (event, args)."""

    def __init__(self, state: AppState):
        self.events: list[tuple[str, tuple]] = []
        for name in ("opened", "closed", "refreshed", "selection_changed", "details_changed", "next_step_changed",
                     "view_requested", "error"):
            getattr(state, name).connect(lambda *a, name=name: self.events.append((name, a)))
        state.status.changed.connect(lambda m: self.events.append(("status", (m,))))
        state.map.preview_changed.connect(lambda *a: self.events.append(("map", a)))
        state.map.message.connect(lambda t: self.events.append(("map_message", (t,))))

    def last(self, name: str):
        return next((a for n, a in reversed(self.events) if n == name), None)

    def names(self) -> list[str]:
        return [n for n, _ in self.events]


def test_open_refresh_select_and_details_reach_the_subscribers(processed_copy):
    from projects.results.state import epoch_state

    st = AppState()
    rec = Recorder(st)
    assert st.open(processed_copy)
    assert [n for n in rec.names() if n in ("opened", "refreshed")] == ["opened", "refreshed"]
    assert rec.last("opened") == ("Test bridge",)
    snap = rec.last("refreshed")[0]
    assert snap.epochs == ["2026-03-02", "2026-03-09", "2026-03-16"] and "M3" in snap.histories
    with Campaign.open(processed_copy, writable=False) as c:  # the tree shows the one decided state
        assert [e["state"] for e in snap.status["epochs"]] == [epoch_state(c, e)[0] for e in snap.epochs]
    assert "Test bridge" in rec.last("details_changed")[0]
    st.select(reflector="M3")
    assert st.selection.focus == ("reflector", "M3") and "Reflector M3" in rec.last("details_changed")[0]
    n = len(rec.events)
    st.select(reflector="M3")  # no change, no event
    assert len(rec.events) == n
    st.select(epoch="2026-03-09")
    assert st.selection.reflector == "M3" and st.selection.focus == ("epoch", "2026-03-09")
    assert "Centroids" in rec.last("details_changed")[0]
    st.request_view("map")
    assert rec.last("view_requested") == ("map",)
    with pytest.raises(ValueError):
        st.request_view("nowhere")
    st.close()
    assert rec.last("closed") == () and not st.is_open


def test_a_folder_without_campaign_is_one_message_in_the_applications_words(tmp_path):
    st = AppState()
    rec = Recorder(st)
    assert not st.open(tmp_path)
    title, message = rec.last("error")
    assert title == "Open campaign" and "File ▸ New campaign…" in message and "bridgesurvey" not in message
    assert not st.is_open


def test_the_next_step_leads_through_a_visit(field_copy, tmp_path):
    from lidar.simulate.files import simulate_fine
    from tests.projects.conftest import MODEL

    folder = actions.create_campaign(folder=str(tmp_path / "camp"), name="Visit", layout=str(field_copy / "layout.csv"),
                                     span_m=40.0, diameter_mm=50.0)
    st = AppState()
    steps = []
    st.next_step_changed.connect(lambda s: steps.append(s.command))
    st.open(folder)
    assert st.next.command == "add_epoch"
    label = actions.add_epoch(st.access, {"label": "v0", "datetime": "2026-04-01T09:00:00Z", "notes": "",
                                          "coarse": str(field_copy / "v0" / "coarse.laz"), "fines": []},
                              lambda *a: None)
    st.refresh()
    st.select(epoch=label)
    assert st.next.command == "plan" and st.next.epoch == "v0" and "plan" in st.next.text.lower()
    plan = actions.plan(st.access, "v0", lambda *a: None)
    st.refresh()
    assert st.next.command == "add_fine"
    fine, _ = simulate_fine(field_copy / "v0", plan.rois, model=MODEL, name="fine-state.laz")
    actions.add_fine(st.access, "v0", [str(fine)], lambda *a: None)
    st.refresh()
    assert st.next.command == "check"
    actions.check(st.access, "v0", lambda *a: None)
    st.refresh()
    assert st.next.command == "process"
    actions.process(st.access, lambda *a: None)
    st.refresh()
    assert st.next.command == "report"
    assert steps == ["add_epoch", "plan", "add_fine", "check", "process", "report"]
    assert "Epoch ▸ Add epoch…" in st.next.tooltip
    # a second station of the same visit, through the application: added and planned in one job
    new, plans = actions.add_setup(st.access, "v0", str(field_copy / "v1" / "coarse.laz"), lambda *a: None)
    assert new == [2] and len(plans) == 1 and len(plans[0].rois) >= 5
    with Campaign.open(folder, writable=False) as c:
        assert c.setups("v0") == [1, 2] and c.plan("v0", 2) is not None and c.last_setup("v0") == 2


def test_next_step_prefers_the_selected_epoch_then_the_latest_with_work_left():
    eps = [{"epoch": "a", "state": "scanned", "stale": "new"}, {"epoch": "b", "state": "processed", "stale": ""},
           {"epoch": "c", "state": "planned", "stale": "new"}]
    assert next_step({"epochs": eps}, "a").command == "check"
    assert next_step({"epochs": eps}, "b").command == "add_fine" and next_step({"epochs": eps}, "b").epoch == "c"
    assert next_step({"epochs": eps}, None).epoch == "c"
    stale = [{"epoch": "a", "state": "processed", "stale": "parameters changed"}]
    assert next_step({"epochs": stale}, None).command == "process"


def test_the_map_keeps_unsaved_edits_across_a_refresh(processed_copy):
    st = AppState()
    rec = Recorder(st)
    st.open(processed_copy)
    st.show_view("map")
    assert st.map.label == "2026-03-16" and len(st.map.editor.rois) == 9  # no selection: the latest epoch
    label, _preview, plan = rec.last("map")
    assert label == "2026-03-16" and plan is not None
    st.map.editor.remove(["M5"])
    st.refresh()
    assert st.map.editor.dirty and len(st.map.editor.rois) == 8  # the edit is not thrown away
    st.map.editor.revert()
    st.refresh()
    assert not st.map.editor.dirty and len(st.map.editor.rois) == 9
    free = st.map.free_targets(st.snapshot.reflectors)
    assert free == []
    st.select(epoch="2026-03-02")
    assert st.map.label == "2026-03-02"


def test_failed_and_cancelled_jobs_say_what_happened():
    clock = [0.0]
    s = StatusLine(clock=lambda: clock[0])
    s.started("Importing epoch e1")
    s.progress(0.5, "reading coarse.laz")
    assert s.message.text == "Importing epoch e1: reading coarse.laz" and s.running
    s.failed("x.laz: not a scan")
    s.finished(ok=False)
    assert s.message.text == "Importing epoch e1 failed: x.laz: not a scan" and not s.running
    assert not s.info("hovering")  # a failure stays until the next job
    s.started("Evaluating scanner stations")
    s.cancelling()
    s.progress(0.6, "120 of 600 stations")  # a late progress line does not replace "cancelling…"
    assert s.message.text == "Evaluating scanner stations: cancelling…"
    s.cancelled()
    s.finished(ok=False)
    assert s.message.text == "Evaluating scanner stations: cancelled" and s.message.kind == "cancelled"


def test_a_jobs_result_line_is_not_overwritten():
    clock = [0.0]
    s = StatusLine(clock=lambda: clock[0])
    s.started("Writing the report")
    s.result("report written to /tmp/r.pdf")
    s.finished(ok=True)
    assert s.message.text == "report written to /tmp/r.pdf"
    clock[0] = 0.01
    assert not s.info("something else") and s.message.text == "report written to /tmp/r.pdf"
    clock[0] = 60.0
    assert s.info("something else")
    s.started("Processing")
    s.finished(ok=True)
    assert s.message.text == "Processing: done"


def test_job_failures_reach_the_user_in_the_applications_words():
    st = AppState()
    errors = []
    st.error.connect(lambda title, msg: errors.append((title, msg)))
    st.status.started("Checking the fine scans of e1")
    st.job_failed("Checking the fine scans of e1",
                  "epoch e1 has no fine scans yet; import them with 'bridgesurvey add-fine' first", "error")
    assert errors == [("Checking the fine scans of e1", "epoch e1 has no fine scans yet; import them with "
                       "Epoch ▸ Add fine scans to the selected epoch… first")]
    assert st.status.message.kind == "failed" and "bridgesurvey" not in st.status.message.text
    st.status.started("Processing")
    st.job_failed("Processing", "cancelled by the user", "cancelled")
    assert len(errors) == 1 and st.status.message.text == "Processing: cancelled"


def _raised_messages(root: Path) -> list[str]:
    """The literal text of every message raised in ``root``'s sources (f-string holes as '{}')."""
    out = []
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
                for arg in node.exc.args:
                    parts = [v.value if isinstance(v, ast.Constant) else "{}" for v in
                             (arg.values if isinstance(arg, ast.JoinedStr) else [arg])]
                    text = "".join(p for p in parts if isinstance(p, str))
                    if text:
                        out.append(text)
    return out


def test_every_campaign_message_naming_a_command_line_reads_in_the_applications_words():
    root = Path(__file__).resolve().parents[4] / "projects"
    cli = [m for m in _raised_messages(root) if "bridgesurvey" in m or re.search(r"(?<![\w-])--[a-z]", m)]
    assert len(cli) >= 10  # the scan finds them
    for m in cli:
        words = in_app_words(m)
        assert "bridgesurvey" not in words and not re.search(r"(?<![\w-])--[a-z]", words), (m, words)
    assert in_app_words("give another --name") == "give another Series name"
    assert in_app_words("a-b--c is 3--4 mm") == "a-b--c is 3--4 mm"  # no option: left alone


def test_dialog_folders_are_remembered_per_kind(tmp_path):
    store: dict = {}
    f = LastFolders(store, fallback=str(tmp_path))
    assert f.start("scans") == str(tmp_path)
    (tmp_path / "visit").mkdir()
    f.remember("scans", tmp_path / "visit" / "coarse.laz")
    f.remember("outputs", tmp_path)
    assert f.start("scans") == str(tmp_path / "visit") and f.start("outputs", "r.pdf") == str(tmp_path / "r.pdf")
    assert LastFolders(store).start("scans") == str(tmp_path / "visit")  # kept in the store
    with pytest.raises(ValueError):
        f.remember("nonsense", tmp_path)


def test_change_colours_come_from_the_structure_not_the_far_ground():
    rng = np.random.default_rng(3)
    deck = np.column_stack([rng.uniform(0, 40, 3000), rng.uniform(-2, 2, 3000), rng.uniform(6, 7, 3000)])
    ground = np.column_stack([rng.uniform(-30, 70, 6000), rng.uniform(-30, 30, 6000), rng.uniform(-1, 0, 6000)])
    ground = ground[np.abs(ground[:, 1]) > 5]  # beside the bridge
    xyz = np.vstack([deck, ground])
    values = np.r_[rng.normal(-4.0, 0.3, len(deck)), rng.choice([-9.7, 9.7], len(ground))]
    markers = np.array([[0.0, 0.0, 6.5], [40.0, 0.0, 6.5], [20.0, 0.0, 6.8]])
    scale = change_scale(xyz, values, markers)
    assert 4.0 < scale.limit < 5.5 and scale.source == "the deck and piers" and "±" in scale.legend
    assert change_scale(xyz, values, np.zeros((0, 3))).limit > 9.0  # without targets: every point
    keep = budget_indices(1_500_000)
    assert len(keep) <= POINT_BUDGET and keep[0] == 0


def test_analysis_inputs_from_the_application_and_a_refused_prediction(processed_copy, tmp_path):
    from app.gui.state.campaign_access import CampaignAccess

    access = CampaignAccess(processed_copy)
    temp = tmp_path / "temperature.csv"
    t = np.arange(np.datetime64("2026-02-28T00:00"), np.datetime64("2026-03-18T00:00"), np.timedelta64(1, "h"))
    temp.write_text("time,temperature_degC\n" + "".join(f"{x}Z,{10 + 5 * np.sin(k / 24):.2f}\n"
                                                        for k, x in enumerate(t)))
    name, summary = actions.import_env(access, {"file": str(temp), "kind": "temperature", "name": None,
                                                "column": None, "unit": None, "timezone": "UTC"}, lambda *a: None)
    assert name == "temperature" and summary["rows"] == len(t)
    actions.add_event(access, {"date": "2026-03-05", "kind": "construction", "label": "slab", "load_kn_m": None})
    pred = tmp_path / "prediction.csv"
    pred.write_text("age_days,M1,M3\n0,0,0\n400,-1,-2\n")
    before = snapshot(processed_copy)
    with pytest.raises(Exception) as err:  # by concrete age, cast after the epochs: refused, nothing kept
        actions.import_prediction(access, {"file": str(pred), "align_at": None, "casting_date": "2027-01-01"},
                                  lambda *a: None)
    assert "prediction" in str(err.value) or "overlap" in str(err.value)
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.settings().get("casting_date") is None
    after = snapshot(processed_copy)
    assert {k: v for k, v in after.items() if not k.endswith(".sqlite")} == \
        {k: v for k, v in before.items() if not k.endswith(".sqlite")}
    out = actions.import_prediction(access, {"file": str(pred), "align_at": None, "casting_date": "2026-01-01"},
                                    lambda *a: None)
    assert set(out) == {"M1", "M3"}
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.settings()["casting_date"].startswith("2026-01-01") and len(c.events.all()) == 1
    assert "flagged" in actions.set_limit(access, "M3", "prediction:2")

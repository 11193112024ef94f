"""The GUI's actions are plain functions: they run on a campaign without Qt or a window."""
import json

import pytest

from app.gui import actions
from app.gui.state.campaign_access import CampaignAccess
from common.errors import InputError
from projects.store.campaign import Campaign


def _progress(seen):
    return lambda f, msg="": seen.append(f)


def test_actions_change_the_campaign_and_report_progress(processed_copy, tmp_path):
    access = CampaignAccess(processed_copy)
    actions.set_limit(access, "*", "abs:4,8")
    actions.set_parameter(access, "min_points", "1500")
    with pytest.raises(InputError):
        actions.set_parameter(access, "min_points", "a lot")
    actions.replace_reflector(access, "M5", "M5b", "2026-03-10")
    with access.read() as c:
        assert c.limit_for("M1").warning_mm == 4.0 and c.settings()["min_points"] == 1500
        assert c.reflector("M5b").replaces == "M5"
        plan = c.plan("2026-03-09")
    edited = [r for r in plan.rois if not r.closure][:-1]  # the closure window follows its target's window
    from lidar.plan import with_rois

    actions.save_plan(access, "2026-03-09", with_rois(plan, edited))
    with access.read() as c:
        saved = [r for r in c.plan("2026-03-09").rois if not r.closure]
        assert c.stored_plan("2026-03-09").edited and saved == edited
    seen = []
    summary = actions.process(access, _progress(seen))
    assert seen and seen[-1] == pytest.approx(1.0) and not summary.failed
    csv_path = actions.export_csv(access, tmp_path / "d.csv")
    assert csv_path.read_text().startswith("epoch,datetime,reflector")
    doc = actions.analyse(access)
    assert {t["reflector"] for t in doc["targets"]} >= {"M1", "M3"}
    status = actions.fleet_status(str(processed_copy.parent))
    assert json.dumps(status) and status["bridges"][0]["name"]


def test_a_refused_action_leaves_the_campaign_as_it_was(processed_copy):
    access = CampaignAccess(processed_copy)
    before = (processed_copy / "campaign.sqlite").read_bytes()
    with pytest.raises(InputError):
        actions.retire_reflector(access, "M1", "not-a-date")
    with pytest.raises(InputError):
        actions.set_limit(access, "nobody", "abs:1,2")
    assert (processed_copy / "campaign.sqlite").read_bytes() == before
    with Campaign.open(processed_copy, writable=False) as c:
        assert not c.reflector("M1").retired

"""The store's set-ups and poses: each file's set-up and frame, per-set-up plans and centroids with digests, repair."""
from __future__ import annotations

import json
import sqlite3

import numpy as np
import pytest

from common.errors import InputError
from lidar.io.poses import FileFrame
from lidar.layout import read_layout_csv
from lidar.scanner_catalogue import get_scanner
from projects.store import digests, journal, schema
from projects.store.campaign import DB_NAME, Campaign
from projects.store.repair import repair_campaign
from projects.store.verify import verify_store

WHEN = "2026-03-02T09:00:00+00:00"


@pytest.fixture
def camp(field_copy, tmp_path):
    folder = tmp_path / "camp"
    with Campaign.create(folder, name="Set-ups", layout=read_layout_csv(field_copy / "layout.csv")) as c:
        c.add_epoch("e1", WHEN, field_copy / "v0" / "coarse.laz")
    return folder


def _centroids(c, label):
    from lidar.simulate.epochs import LAB_POSITIONS, fine_epoch
    from lidar.simulate.scene import EpochConditions

    cents, _, _, _ = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=3)
    return cents


def test_a_visit_gets_set_ups_and_each_file_its_own(camp, field_copy):
    with Campaign.open(camp) as c:
        assert c.setups("e1") == [1] and c.last_setup("e1") == 1
        assert c.add_setup("e1", field_copy / "v1" / "coarse.laz") == [2]
        assert c.setups("e1") == [1, 2] and c.last_setup("e1") == 2
        assert sorted(f.setup for f in c.files("e1", setup=None)) == [1, 2]
        assert [f.original_path for f in c.files("e1", "coarse", setup=2)] == [str((field_copy / "v1" / "coarse.laz")
                                                                                   .resolve())]
        assert len(c.files("e1")) == 1  # set-up 1 by default: one scanner frame, as before set-ups
        inp = c.epoch_inputs("e1", setup=2)
        assert inp.setup == 2 and inp.setups == (1, 2) and len(inp.coarse) == 1 and not inp.fine
        with pytest.raises(InputError, match="no set-up 3; its set-ups are 1, 2"):
            c.check_setup("e1", 3)
        with pytest.raises(InputError, match="no set-up 3"):
            c.import_files("e1", [field_copy / "v2" / "coarse.laz"], "fine", setup=3)
        log = [e for e in c.log() if e.action == "import"]
        assert log[-1].details["setups"] == [2]


def test_a_set_up_keeps_its_own_scanner(camp, field_copy):
    with Campaign.open(camp) as c:
        c.add_setup("e1", field_copy / "v1" / "coarse.laz")
        c.set_profile(get_scanner("Leica RTC360"), epoch="e1", setup=2)
        assert c.profile_for("e1", 2).name == "Leica RTC360" and c.profile_for("e1").name == c.profile.name
        entries = [e for e in journal.entries(camp) if e.get("kind") == "epoch-scanner"]
        assert entries[-1]["setup"] == 2


def test_plans_previews_and_centroids_of_further_set_ups_round_trip_under_their_digests(camp, field_copy):
    with Campaign.open(camp) as c:
        c.add_setup("e1", field_copy / "v1" / "coarse.laz")
        c.save_plan("e1", {"epoch": "e1", "setup": 2, "rois": [], "scanner_profile": c.profile.to_dict(),
                           "total_seconds": 0.0}, "h2", preview=(b"\x00" * 16, "{}"), setup=2)
        assert c.result("e1", 2).stage == "planned" and c.result("e1") is None
        assert c.stored_plan("e1", 2).plan_json["setup"] == 2 and c.stored_plan("e1") is None
        cents = _centroids(c, "e1")
        one = next(iter(cents.values()))
        closure = {one.reflector: one}
        c.save_centroids("e1", cents, "m2", {}, closures=closure, time_source="plan", setup=2)
        got = c.centroids("e1", 2)
        assert sorted(got) == sorted(cents) and c.result("e1", 2).stage == "measured"
        for k, v in cents.items():
            assert np.allclose(got[k].xyz_socs, v.xyz_socs) and np.allclose(got[k].cov, v.cov)
            assert got[k].flags == v.flags and got[k].n_points == v.n_points
        assert list(c.closure_centroids("e1", 2)) == [one.reflector] and c.time_source("e1", 2) == "plan"
        assert c.centroids("e1") == {} and c.damaged_results() == []
        c.conn.execute("UPDATE setup_results SET centroids = replace(centroids, '\"n\": ', '\"n\": 1') "
                       "WHERE epoch = 'e1'")
        c.conn.commit()
        assert c.result("e1", 2) is None and c.centroids("e1", 2) == {}  # damaged: stale, never served
        findings = [f.line() for f in verify_store(c)]
        assert any("set-up centroids of epoch e1, set-up 2: damaged" in f and "measure the set-up again" in f
                   for f in findings)


def test_a_file_read_through_a_pose_keeps_its_frame(camp, field_copy):
    pose = np.eye(4)
    pose[:3, 3] = [2.5e6, 5.6e6, 100.0]
    frame = FileFrame(pose=pose, carry=True, source="pose", given="sop.txt")
    with Campaign.open(camp) as c:
        c.add_setup("e1", field_copy / "v1" / "coarse.laz", frames_of=lambda path, fallback: [frame])
        (f,) = c.files("e1", "coarse", setup=2)
        assert f.setups == (2,) and np.allclose(f.frame_for(2).pose, pose) and f.frame_for(2).carry
        assert f.frame_for(1) is None
        seen = []
        c.import_files("e1", [field_copy / "v2" / "coarse.laz"], "fine",
                       frames_of=lambda path, fallback: seen.append(fallback) or [FileFrame()])
        assert seen[0] is not None and np.allclose(seen[0].pose, pose)  # the set-up's pose offered to its fine scans
        assert c.files("e1", "fine", setup=2)[0].frame is None


def test_repair_registers_a_set_up_file_again_with_its_set_up_and_frame(camp, field_copy):
    pose = np.eye(4)
    pose[:3, 3] = [1000.0, 2000.0, 10.0]
    frame = FileFrame(pose=pose, carry=True, source="origin", given="1000,2000,10")
    with Campaign.open(camp) as c:
        c.add_setup("e1", field_copy / "v1" / "coarse.laz", frames_of=lambda path, fallback: [frame])
        (f,) = c.files("e1", setup=2)
        c.conn.execute("DELETE FROM files WHERE setup = 2")
        c.conn.commit()
        assert c.setups("e1") == [1]
        report = repair_campaign(c)
        assert any("registered again" in line for line in report.done)
        (g,) = c.files("e1", setup=2)
        assert g.stored_path == f.stored_path and json.loads(g.frame) == json.loads(f.frame)


def test_a_campaign_of_version_10_reads_its_files_as_set_up_1(camp):
    conn = sqlite3.connect(camp / DB_NAME)
    for table in ("setup_plans", "setup_previews", "setup_results"):
        conn.execute(f"DROP TABLE {table}")
    for column in ("setup", "frame"):
        conn.execute(f"ALTER TABLE files DROP COLUMN {column}")
    for g in digests.INPUTS.values():  # and what version 12 added
        conn.execute(f"ALTER TABLE {g.table} DROP COLUMN {g.column}")
    conn.execute("DROP TABLE archived_files")  # and version 13
    conn.execute("UPDATE meta SET value = '10' WHERE key = 'schema_version'")
    conn.commit()
    conn.close()
    with Campaign.open(camp) as c:
        assert schema.version_of(c.conn) == schema.SCHEMA_VERSION == 13
        (f,) = c.files("e1", setup=None)
        assert f.setup == 1 and f.frame is None and c.setups("e1") == [1] and c.damaged_results() == []

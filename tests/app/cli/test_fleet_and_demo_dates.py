"""'fleet status' lists a missing bridge as unreadable; the demo's visits end before today (issue 25 item 11)."""
from __future__ import annotations

import datetime as dt
import doctest
import json
from pathlib import Path

from app.cli.main import main
from projects.results.status import campaign_status
from projects.store.campaign import Campaign


def test_fleet_status_lists_a_missing_folder_of_a_fleet_file_as_unreadable(processed_copy, tmp_path, capsys):
    listing = tmp_path / "fleet.txt"
    listing.write_text(f"{processed_copy}\nbridges/gone  # demolished, or a typo\n")
    assert main(["fleet", "status", str(listing)]) == 0
    out = capsys.readouterr().out
    assert "unreadable" in out and "gone" in out and "no such folder" in out and "1 unreadable" in out
    assert main(["fleet", "status", str(listing), "--json"]) == 0
    bridges = {Path(b["folder"]).name: b for b in json.loads(capsys.readouterr().out)["bridges"]}
    assert bridges["gone"]["error"].startswith("no such folder") and bridges["camp"]["error"] is None
    assert bridges["camp"]["epochs"] == 3
    assert main(["fleet", "status", str(tmp_path / "typo")]) == 1  # a root given itself is still a mistake
    assert "no such folder" in capsys.readouterr().err


def test_the_demo_ends_before_the_day_it_is_built():
    import projects.demo as demo

    assert doctest.testmod(demo).failed == 0
    for today in (dt.date(2026, 12, 1), dt.date(2026, 11, 30), dt.date(2027, 3, 7), dt.date.today()):
        for weeks in (2, 52):
            start = demo.demo_start(weeks, today=today)
            last = start + dt.timedelta(weeks=weeks - 1)
            assert last.date() < today and (today - last.date()).days <= 7
            assert last.weekday() == 0 and last.time() == demo.VISIT_TIME


def test_the_demo_says_how_to_open_its_folder(tmp_path, capsys):
    """'./run demo DIR' ends with how to open DIR (issue 41 item 7): './run gui' alone opens another folder."""
    from app.cli.main import main

    folder = tmp_path / "my demo"
    assert main(["demo", str(folder), "--weeks", "2"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == (f"open it in the application: ./run gui '{folder}' (from the source folder; installed: "
                    f"bridgesurvey-gui '{folder}'); on the command line: bridgesurvey status '{folder}'")
    # the finished demo is up to date: its air series was imported before its visits were processed
    with Campaign.open(folder, writable=False) as c:
        assert [e["stale"] for e in campaign_status(c)["epochs"]] == ["", ""]

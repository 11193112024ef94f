"""Series imports as a surveyor's files come (issue 41 item 6), and the campaign's time zone: set at init, changed
with settings, shown by status, and named by every import."""
import json
import subprocess
import sys

import pytest

from tests.projects.campaign_helpers import snapshot

LAYOUT = ("id,group,x,y,z\nR1,reference,0,0,2\nR2,reference,0,3,2\nR3,reference,40,0,2\nR4,reference,40,3,2\n"
          "M1,measurement,10,1.5,6\nM2,measurement,20,1.5,6\nM3,measurement,30,1.5,6\n")


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, args)], capture_output=True, text=True)


@pytest.fixture
def campaign(tmp_path):
    (tmp_path / "layout.csv").write_text(LAYOUT)
    camp = tmp_path / "camp"
    r = _cli("init", camp, "--name", "River bridge", "--layout", tmp_path / "layout.csv", "--timezone",
             "Europe/Berlin")
    assert r.returncode == 0, r.stderr
    assert "time zone Europe/Berlin" in r.stdout
    return camp


def test_the_campaign_time_zone_is_shown_changed_and_refused_when_unknown(campaign):
    r = _cli("status", campaign)
    assert r.returncode == 0 and "time zone Europe/Berlin" in r.stdout.splitlines()[0]
    assert json.loads(_cli("status", campaign, "--json").stdout)["timezone"] == "Europe/Berlin"
    before = snapshot(campaign)
    r = _cli("settings", campaign, "timezone", "Mars/Olympus")
    assert r.returncode == 1 and r.stderr.strip().splitlines() == [
        "bridgesurvey: error: time zone 'Mars/Olympus' is not known; use an IANA name such as Europe/Berlin or an "
        "offset such as +09:00"]
    assert snapshot(campaign) == before
    r = _cli("settings", campaign, "timezone", "+09:00")
    assert r.returncode == 0 and "timezone = +09:00 (was Europe/Berlin)" in r.stdout
    assert "time zone +09:00" in _cli("status", campaign).stdout
    assert ["timezone", "+09:00", "UTC"] in [ln.split() for ln in _cli("settings", campaign).stdout.splitlines()]


def test_a_humidity_file_with_a_bad_row_is_imported_and_says_its_zone(campaign, tmp_path):
    rows = ["time,humidity_pct"] + [f"2026-03-01 {h:02d}:00,{60 + h / 2}" for h in range(24)]
    rows.insert(7, "2026-03-01 05:30,,")  # a field too many: the surveyor's logger hiccupped
    (tmp_path / "rh.csv").write_text("\n".join(rows) + "\n")
    r = _cli("env", "import", campaign, tmp_path / "rh.csv", "--kind", "humidity")
    assert r.returncode == 0, r.stderr
    out = r.stdout.splitlines()
    assert "24 rows" in out[0] and "column 'humidity_pct' in pct" in out[0]
    assert out[1] == "  times: without an offset, read as Europe/Berlin time"
    assert out[2] == "  1 bad row(s) of 25 left out (could not be read):"
    assert out[3] == "    line 8: 3 fields where the header has 2 fields"
    r = _cli("env", "list", campaign, "--json")
    stored = json.loads(r.stdout)[0]
    assert stored["options"]["timezone"] == "Europe/Berlin" and stored["summary"]["start"].startswith(
        "2026-02-28T23:00")  # 00:00 in Berlin is 23:00 UTC the day before


def test_a_semicolon_file_with_decimal_commas_and_a_named_column(campaign, tmp_path):
    rows = ["Zeit;Temperatur;Feuchte"] + [f"2026-03-01T{h:02d}:00;{h},5;{50 + h},0" for h in range(24)]
    (tmp_path / "wetter.csv").write_text("\n".join(rows) + "\n")
    r = _cli("env", "import", campaign, tmp_path / "wetter.csv", "--kind", "temperature")
    assert r.returncode == 1 and "no time column" in r.stderr  # 'Zeit' is not a name the reader knows
    rows[0] = "time;Temperatur;Feuchte"
    (tmp_path / "wetter.csv").write_text("\n".join(rows) + "\n")
    r = _cli("env", "import", campaign, tmp_path / "wetter.csv", "--kind", "temperature")
    assert r.returncode == 1 and r.stderr.strip().endswith(
        "cannot tell which column holds the air temperature (the columns are time, Temperatur, Feuchte); name it "
        "with --column")
    r = _cli("env", "import", campaign, tmp_path / "wetter.csv", "--kind", "temperature", "--column", "Temperatur",
             "--timezone", "UTC")
    assert r.returncode == 0, r.stderr
    assert "24 rows" in r.stdout and "times: without an offset, read as UTC time" in r.stdout
    assert "bad row" not in r.stdout
    from projects.series.environment import load_env
    from projects.store.campaign import Campaign

    with Campaign.open(campaign, writable=False) as c:
        s = load_env(c, kind="temperature")[0]
    assert s.value[3] == 3.5 and s.unit == "°C"

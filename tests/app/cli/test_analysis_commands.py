"""env import, event add and analyse from the command line, with bad input left without a trace."""
import datetime as dt
import json
import subprocess
import sys

import numpy as np
import pytest

from tests.app.cli.conftest import error_lines
from tests.projects.campaign_helpers import snapshot


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, args)], capture_output=True, text=True)


def _temperature_csv(path, *, unit="degF", start="2026-02-20", days=40, sep=";"):
    t0 = dt.datetime.fromisoformat(start)
    rows = [f"date{sep}time{sep}temp [{unit}]"]
    for h in range(days * 24):
        t = t0 + dt.timedelta(hours=h)
        c = 8 + 5 * np.sin(2 * np.pi * (h % 24 - 9) / 24)
        v = c * 9 / 5 + 32 if unit == "degF" else c + 273.15 if unit == "K" else c
        rows.append(f"{t:%Y-%m-%d}{sep}{t:%H:%M}{sep}{v:.2f}")
    rows.insert(5, f"2026-02-20{sep}04:30{sep}warm")  # one bad row, reported
    path.write_text("\n".join(rows) + "\n")
    return path


def test_env_import_converts_units_and_is_listed(processed_copy, tmp_path):
    f = _temperature_csv(tmp_path / "air.csv")
    r = _cli("env", "import", processed_copy, f, "--kind", "temperature", "--timezone", "+09:00")
    assert r.returncode == 0, r.stderr
    assert "1 bad row" in r.stdout
    r = _cli("env", "list", processed_copy, "--json")
    rows = json.loads(r.stdout)
    assert rows[0]["kind"] == "temperature" and rows[0]["options"]["unit"] == "°C"
    from projects.series.environment import load_env
    from projects.store.campaign import Campaign

    with Campaign.open(processed_copy, writable=False) as c:
        s = load_env(c, kind="temperature")[0]
    assert 2.5 < np.nanmin(s.value) < 3.5 and 12.5 < np.nanmax(s.value) < 13.5  # degF -> degC
    kept = [p for p in (processed_copy / "environment").iterdir() if not p.name.startswith(".")]
    assert len(kept) == 1 and not kept[0].stat().st_mode & 0o222  # a read-only copy in the campaign


@pytest.mark.parametrize("args, message", [
    (["--kind", "temperature", "--unit", "furlong"], "unknown unit"),
    (["--kind", "wind"], "invalid choice"),
])
def test_bad_series_change_nothing(processed_copy, tmp_path, args, message):
    f = _temperature_csv(tmp_path / "air.csv")
    before = snapshot(processed_copy)
    r = _cli("env", "import", processed_copy, f, *args)
    assert r.returncode != 0 and message in r.stderr
    assert snapshot(processed_copy) == before


def test_events_and_analyse_write_the_contract(processed_copy, tmp_path):
    _cli("env", "import", processed_copy, _temperature_csv(tmp_path / "air.csv", unit="K"), "--kind", "temperature")
    before = snapshot(processed_copy)
    r = _cli("event", "add", processed_copy, "--date", "2020-01-01", "--kind", "load", "--label", "too early")
    assert r.returncode == 1 and "outside the campaign" in r.stderr and len(error_lines(r.stderr)) == 1
    assert snapshot(processed_copy) == before
    r = _cli("event", "add", processed_copy, "--date", "2026-03-12", "--kind", "construction", "--label", "slab",
             "--load-kn-m", "12.5")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "an"
    r = _cli("analyse", processed_copy, "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "analysis.json").read_text())
    assert doc == json.loads(r.stdout)
    assert [t["reflector"] for t in doc["targets"]] == ["M1", "M2", "M3", "M4", "M5"]
    for t in doc["targets"]:
        for key in ("reflector", "thermal_mm_per_degC", "thermal_sigma", "events", "prediction_offset_mm",
                    "prediction_residual_rms_mm", "trend_mm_per_year", "projection"):
            assert key in t
        # three epochs: nothing can be fitted, and no number is invented
        assert t["thermal_mm_per_degC"] is None and t["notes"] and "too few" in t["notes"][0]
    assert (out / "analysis-M3.png").exists()


def test_analyse_before_processing_is_one_line(field_copy, tmp_path):
    camp = tmp_path / "camp"
    _cli("init", camp, "--name", "x", "--layout", field_copy / "layout.csv")
    r = _cli("analyse", camp, "--out", tmp_path / "an")
    assert r.returncode == 1 and "no displacements yet" in r.stderr


def _prediction_csv(path, ids, start="2026-02-20", days=40, offset=5.0):
    t0 = dt.date.fromisoformat(start)
    rows = ["date," + ",".join(ids)]
    for k in range(0, days, 2):
        rows.append(f"{t0 + dt.timedelta(days=k)}," + ",".join(f"{offset - 0.1 * k:.3f}" for _ in ids))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_prediction_import_aligns_flags_departures_and_refuses_unknown_targets(processed_copy, tmp_path):
    from projects.results.table import displacement_table
    from projects.store.campaign import Campaign

    before = snapshot(processed_copy)
    bad = _prediction_csv(tmp_path / "bad.csv", ["M1", "M9"])
    r = _cli("prediction", "import", processed_copy, bad)
    assert r.returncode == 1 and "M9" in r.stderr and "not in the campaign" in r.stderr
    age = tmp_path / "age.csv"
    age.write_text("age_days,M1\n100,1\n200,2\n")
    r = _cli("prediction", "import", processed_copy, age)
    assert r.returncode == 1 and "casting date" in r.stderr
    assert snapshot(processed_copy) == before
    good = _prediction_csv(tmp_path / "fem.csv", ["M1", "M2", "M3", "M4", "M5"])
    r = _cli("prediction", "import", processed_copy, good, "--align-at", "2026-03-02")
    assert r.returncode == 0, r.stderr
    with Campaign.open(processed_copy, writable=False) as c:
        rows = {(x["epoch"], x["reflector"]): x for x in displacement_table(c)}
    first = rows[("2026-03-02", "M3")]
    assert first["departure_mm"] == 0.0  # aligned there
    later = rows[("2026-03-16", "M3")]
    assert later["predicted_mm"] == pytest.approx(first["predicted_mm"] - 1.4, abs=0.01)
    assert _cli("limit", processed_copy, "--rule", "prediction:0.5").returncode == 0
    with Campaign.open(processed_copy, writable=False) as c:
        flagged = [x for x in displacement_table(c) if "departs_from_prediction" in x["flags"]]
    assert flagged and all(abs(x["departure_mm"]) > 0.5 for x in flagged)
    assert _cli("settings", processed_copy, "casting_date", "2025-06-01").returncode == 0
    r = _cli("prediction", "import", processed_copy, age)
    assert r.returncode == 1 and "does not overlap" in r.stderr  # ages 100-200 d: before the epochs
    out = tmp_path / "an"
    doc = json.loads(_cli("analyse", processed_copy, "--out", out, "--json").stdout)
    m3 = [t for t in doc["targets"] if t["reflector"] == "M3"][0]
    assert m3["prediction_offset_mm"] is not None and m3["concrete_age_days"][0] > 270

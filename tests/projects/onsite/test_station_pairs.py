"""Two set-ups for one visit: the best second station given the first, and the stations command proposing it."""
from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np

from app.cli.main import main
from lidar.layout import layout_from_model, write_layout_csv
from lidar.simulate import BridgeModel
from lidar.stations import StationPrediction
from projects.onsite.station_pairs import above, chain, combine, propose_pair, propose_three, short_of
from projects.store.campaign import Campaign

LAYOUT = layout_from_model(BridgeModel(spans_m=(39.9, 39.9, 39.9)), noise_m=0.0, rng=np.random.default_rng(0))
DECK = [t for t, g in zip(LAYOUT.ids, LAYOUT.groups, strict=False) if g == "measurement"]
REFS = [t for t, g in zip(LAYOUT.ids, LAYOUT.groups, strict=False) if g == "reference"]


def _station(x: float, sees: list, sigma: float = 0.1) -> StationPrediction:
    hidden = tuple(t for t in LAYOUT.ids if t not in sees)
    return StationPrediction((x, -10.0, 1.5), 600.0, {t: sigma + 0.001 * abs(x - 60) for t in DECK if t in sees},
                             hidden)


END1 = REFS[:4] + DECK[:12]  # spans 1 and 2
END2 = REFS[2:] + DECK[6:]  # spans 2 and 3
MID = REFS[2:6] + DECK[6:12]


def test_a_pair_combines_the_sigmas_of_the_targets_both_see():
    a, b = _station(30, END1), _station(90, END2)
    p = combine(a, b, LAYOUT)
    assert p is not None and not p.hidden and set(p.predicted_sigma_mm) == set(DECK)
    shared = DECK[6]
    want = (a.predicted_sigma_mm[shared] ** -2 + b.predicted_sigma_mm[shared] ** -2) ** -0.5
    assert math.isclose(p.predicted_sigma_mm[shared], want)
    assert p.predicted_sigma_mm[DECK[0]] == a.predicted_sigma_mm[DECK[0]]
    assert p.worst_sigma_mm < math.inf and p.to_json()["seconds"] == 1200.0
    assert set(p.shared) == set(REFS[2:4] + DECK[6:12])


def test_stations_that_share_too_little_are_no_pair():
    assert combine(_station(10, REFS[:2] + DECK[:6]), _station(110, REFS[6:] + DECK[12:]), LAYOUT) is None


def test_targets_seen_weakly_by_one_station_join_nothing():
    """Issue 40: the planner ties set-ups only by targets both see well; a pair that shared only weak sightings was
    proposed before the visit and then refused on site (setup_not_joined)."""
    a, b = _station(30, END1), _station(90, END2)
    both = REFS[2:4] + DECK[6:12]
    keep = [REFS[2], REFS[3], DECK[6]]  # three, spread off a line
    assert combine(a, replace(b, weak=tuple(t for t in both if t not in keep)), LAYOUT).shared == tuple(keep)
    assert combine(a, replace(b, weak=tuple(t for t in both if t not in keep[:2])), LAYOUT) is None  # two: too few


def test_when_no_second_station_joins_the_first_three_set_ups_are_proposed():
    """Issue 40: from one end of a long bridge the other end shares nothing with it; a set-up between them joins
    both, and the three measure every deck target."""
    a = _station(10, REFS[:4] + DECK[:6])
    b = _station(60, REFS[2:6] + DECK[4:14])
    c = _station(110, REFS[4:] + DECK[12:])
    assert combine(a, c, LAYOUT) is None and chain((a, c, b), LAYOUT) is None  # c joins nothing before it
    pair = propose_pair([a, b, c], LAYOUT, first=a)
    assert pair is not None and pair.second is b and set(pair.hidden) == set(DECK[14:])
    three = propose_three([a, b, c], LAYOUT, first=a)
    assert three is not None and three.stations == (a, b, c) and not three.hidden and not above(three, None)
    assert set(three.shared[0]) == set(REFS[2:4] + DECK[4:6]) and set(three.shared[1]) >= set(REFS[4:6])
    assert three.to_json()["seconds"] == 1800.0
    assert propose_three([a, c], LAYOUT, first=a) is None


def test_the_second_set_up_is_the_one_that_improves_the_worst_target_most():
    first = _station(30, END1)
    stations = [first, _station(60, MID), _station(90, END2), _station(115, REFS[6:] + DECK[12:])]
    p = propose_pair(stations, LAYOUT)
    assert p is not None and p.first is first and p.second is stations[2] and not p.hidden
    assert propose_pair([first], LAYOUT) is None


def _deck_of(folder) -> set:
    with Campaign.open(folder, writable=False) as c:
        lay = c.layout()
    return {t for t, g in zip(lay.ids, lay.groups, strict=False) if g == "measurement"}


def test_the_stations_command_proposes_a_pair(processed_copy, tmp_path, capsys):
    area = tmp_path / "area.csv"
    area.write_text("x,y\n2,-20\n38,-20\n38,-8\n2,-8\n")
    out = tmp_path / "stations.json"
    assert main(["stations", str(processed_copy), "--out", str(out), "--area", str(area), "--grid-m", "6",
                 "--pair", "--sigma-mm", "0.01"]) == 0
    d = json.loads(out.read_text())
    text = capsys.readouterr().out
    assert "two set-ups:" in text
    # nothing reaches 0.01 mm: the best station names every deck target it cannot measure to it
    assert "cannot be measured to 0.01 mm" in text and d["sigma_asked_mm"] == 0.01
    assert set(d["best_cannot"]) == _deck_of(processed_copy)
    pair = d["pair"]
    assert pair["first"]["x"] == d["stations"][0]["x"] and len(pair["shared"]) >= 3
    assert pair["worst_sigma_mm"] <= d["stations"][0]["worst_sigma_mm"]


def test_the_best_station_names_what_it_cannot_measure_to_the_sigma_asked_and_the_pair_that_would():
    first = replace(_station(30, END1), weak=(DECK[11],))  # sigma 0.13 mm on what it sees
    why = short_of(first, LAYOUT, 0.12)
    assert set(why) == set(DECK)  # hidden (spans 3), weak (one) or above 0.12 mm (the rest)
    assert why[DECK[0]] == "sigma 0.130 mm" and why[DECK[11]].startswith("weak") and why[DECK[-1]] == "hidden"
    assert set(short_of(first, LAYOUT)) == set(DECK[11:])  # without a sigma asked: the hidden and the weak
    stations = [first, _station(90, END2), _station(60, REFS + DECK, sigma=0.1)]
    pair = propose_pair(stations, LAYOUT, sigma_mm=0.12)
    assert pair is not None and pair.second is stations[2] and above(pair, 0.12) == ()
    assert above(combine(first, stations[1], LAYOUT), 0.12)  # the far end alone leaves span 1 above it


def _stations_from_one_end(tmp_path, capsys, spans_m: tuple[float, ...], first: str):
    """A campaign of ``spans_m`` (its layout only) and ``stations --first`` on it over the whole length beside the deck:
    (campaign folder, stations JSON path, its document, what the command printed)."""
    lay = tmp_path / "layout.csv"
    write_layout_csv(layout_from_model(BridgeModel(spans_m=spans_m, deck_fractions=(0.4, 0.5, 0.6)),
                                       noise_m=0.02, rng=np.random.default_rng(1)), lay)
    camp = tmp_path / "camp"
    assert main(["init", str(camp), "--name", f"{len(spans_m)} spans", "--layout", str(lay),
                 "--span-m", str(spans_m[0])]) == 0
    far = round(sum(spans_m)) + 5
    area = tmp_path / "area.csv"
    area.write_text(f"x,y\n-5,-18\n{far:g},-18\n{far:g},-9\n-5,-9\n")
    out = tmp_path / "stations.json"
    capsys.readouterr()
    assert main(["stations", str(camp), "--out", str(out), "--area", str(area), "--grid-m", "10",
                 "--first", first]) == 0
    return camp, out, json.loads(out.read_text()), capsys.readouterr().out


def test_from_one_end_of_a_long_bridge_before_any_visit_the_pair_and_its_visit_are_proposed(tmp_path, capsys):
    """Issue 40: from the layout alone (no coarse scan yet), set-up 1 at one end of 3 x 39.9 m: the advisor names
    what it cannot measure, the second position near the other end, and the visit planned together from both."""
    camp, out, d, text = _stations_from_one_end(tmp_path, capsys, (39.9,) * 3, "12,-12")
    deck = _deck_of(camp)
    assert d["first"]["x"] == 12.0 and set(d["best_cannot"]) >= {t for t in deck if int(t[1:]) > 12}  # the far span
    assert "from the first station (12.0, -12.0)" in text and "a second set-up at" in text
    pair = d["pair"]
    assert pair["second"]["x"] > 60.0 and not pair["still_short"] and len(pair["shared"]) >= 3  # the other end
    visit = pair["visit"]
    assert [s["setup"] for s in visit["setups"]] == [1, 2] and len(visit["setups"][1]["ties"]) >= 3
    assigned = {t for s in visit["setups"] for t in s["deck_targets_assigned"]}
    assert assigned == deck and not visit["warnings"]  # every deck target from one set-up or the other, joined
    assert "set-up 2 at (" in text and "ties" in text
    assert main(["stations", str(camp), "--out", str(out), "--first", "12"]) == 1
    assert "--first expects x,y" in capsys.readouterr().err


def test_from_one_end_of_a_150_m_bridge_the_stations_command_proposes_three_set_ups(tmp_path, capsys):
    """Issue 40: 5 x 30 m from x = 15 m: no second position joins the first and measures every deck target (near the
    other end it shares only the end piers' targets: not joined on site); three set-ups do, and their visit is
    planned together, joined, in the visit's time (budget_min a set-up)."""
    camp, _, d, text = _stations_from_one_end(tmp_path, capsys, (30.0,) * 5, "15,-12")
    assert d["pair"]["still_short"]  # the best pair leaves a deck target out
    three = d["three"]
    assert [s["x"] for s in three["stations"]][0] == 15.0 and not three["still_short"]
    assert all(len(s) >= 3 for s in three["shared"])
    assert "three set-ups at (15.0, -12.0)" in text and "measure every deck target" in text
    visit = three["visit"]
    assert [s["setup"] for s in visit["setups"]] == [1, 2, 3] and not visit["warnings"]  # joined, time enough
    assert {t for s in visit["setups"] for t in s["deck_targets_assigned"]} == _deck_of(camp)
    assert visit["budget_minutes"] == 180.0

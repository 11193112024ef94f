"""The field error budget through processing: stored model, CSV columns, the air's verdict, the closure, a lost deck."""
from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest

from app.cli.main import main
from common.flags import has
from lidar.centroid import target_centroid
from lidar.simulate import BridgeModel, BridgeScene, EpochConditions, ScannerSetup
from lidar.simulate.epochs import plan_from_truth
from projects.store import digests
from projects.store.campaign import Campaign

BUDGET = ("sigma_noise_mm", "sigma_frame_mm", "sigma_scale_mm", "sigma_bias_mm", "sigma_drift_mm")


def _rows(camp, capsys):
    capsys.readouterr()
    assert main(["displacements", str(camp), "--format", "csv"]) == 0
    return list(csv.DictReader(io.StringIO(capsys.readouterr().out)))


def test_the_model_is_stored_versioned_and_every_row_has_its_budget(processed, capsys):
    bias = json.loads((processed / "bias.json").read_text())
    assert bias["format_version"] == 2 and "range_walk" in bias and "axes" in bias and len(bias["visits"]) == 3
    for r in _rows(processed, capsys):
        if r["epoch"] == r["baseline"] or not r["displacement_mm"]:
            continue
        terms = [float(r[k]) for k in BUDGET]
        assert float(r["sigma_mm"]) == pytest.approx(math.sqrt(sum(t * t for t in terms)), abs=2e-3)  # each printed to 0.001 mm
        assert r["along_mm"] and r["scale_ppm"] and float(r["scale_sigma_ppm"]) > 0


def test_the_air_says_whether_the_instrument_corrected_the_atmosphere(processed_copy, tmp_path, capsys):
    with Campaign.open(processed_copy, writable=False) as c:
        epochs = [(e.label, e.when) for e in c.epochs()]
    # a warm summer epoch after a freezing baseline: the air predicts about -28 ppm, the scans show none
    temp = tmp_path / "air.csv"
    lines = ["time,temperature"]
    for k, (_label, when) in enumerate(epochs):
        value = -2.0 if k == 0 else 28.0
        for m in (-30, 0, 30):
            t = when.timestamp() + 60 * m
            lines.append(f"{np.datetime64(int(t), 's')}Z,{value}")
    temp.write_text("\n".join(lines) + "\n")
    assert main(["env", "import", str(processed_copy), str(temp), "--kind", "temperature"]) == 0
    assert main(["process", str(processed_copy)]) == 0
    with Campaign.open(processed_copy, writable=False) as c:
        flags = c.displacement_set(epochs[-1][0]).flags
    assert has(flags, "atmosphere_corrected_by_instrument"), flags


def test_a_clipped_target_gives_the_centroid_of_an_unclipped_one_within_its_sigma():
    setup = ScannerSetup((14.0, -12.0, 1.5), heading_deg=40.0)
    for rid in ("R2", "M3"):
        got = []
        for clip in (0.0, 0.3):
            scene = BridgeScene(BridgeModel(), EpochConditions(clipped_fraction=clip), setup)
            roi = plan_from_truth(scene, min_points=1500, rng=np.random.default_rng(0)).roi(rid)
            scan, _ = scene.scan(roi.window, rng=np.random.default_rng(5))
            got.append(target_centroid(scan.xyz_socs, scan.intensity, window=roi.window))
        plain, clipped = got
        assert clipped.clipped_fraction > 0.1 and plain.clipped_fraction == 0.0
        d = clipped.xyz_socs - plain.xyz_socs
        assert float(d @ np.linalg.solve(plain.cov + clipped.cov, d)) < 16.0  # within 4 sigma (3 dof)


def test_a_plan_ends_with_its_closure_and_check_reports_it(processed_copy, capsys):
    with Campaign.open(processed_copy, writable=False) as c:
        label = c.epochs()[-1].label
        plan = c.plan(label)
    assert plan.rois[-1].closure and plan.rois[-1].reflector == next(r.reflector for r in plan.rois
                                                                      if r.group == "reference")
    capsys.readouterr()
    rc = main(["check", str(processed_copy), "--epoch", label])
    out = capsys.readouterr().out
    assert rc in (0, 3) and "closure (" in out  # simulated without point times: 'not measured' and why


def test_a_baseline_without_its_deck_is_a_problem_and_processing_completes_twice(processed_copy, capsys):
    """A later epoch measures the deck first seen after a baseline that lost it: no duplicate rows, no traceback."""
    with Campaign.open(processed_copy) as c:
        base = c.settings()["baseline"]
        cents = c.centroids(base)
        deck = [k for k, v in cents.items() if k.startswith("M")]
        with c.transaction() as conn:  # the baseline's deck targets were not found (a stored result, sealed again)
            conn.execute(f"UPDATE centroids SET found = 0, flags = '[\"not_found\"]' WHERE epoch = ? AND reflector IN "
                         f"({','.join('?' * len(deck))})", (base, *deck))
            conn.execute("DELETE FROM displacement_sets")
            digests.seal(conn, "epoch_results", (base,))
        assert not any(v.found for k, v in c.centroids(base).items() if k in deck)
    for _ in range(2):
        capsys.readouterr()
        assert main(["process", str(processed_copy)]) in (0, 3)
    with Campaign.open(processed_copy, writable=False) as c:
        rows = [(r.epoch, r.reflector) for r in c.displacements()]
        state = {e.label: c.displacement_set(e.label) for e in c.epochs()}
    assert len(rows) == len(set(rows))
    assert any(ds is not None and any("deck_not_measured" in f for f in ds.flags) for ds in state.values())


def test_a_sighting_the_field_model_left_out_flags_its_rows():
    """A deck target left out of the field model's fit flags its own row (the baseline's: every epoch's row of
    it); a reference target left out flags every row of the epoch (it sets the frame)."""
    from common.flags import FLAG_FIELD_MISFIT, code
    from lidar.displacement_result import Displacement, EpochDisplacements
    from lidar.stage2 import with_field_misfits
    from lidar.systematic.adjustment import FieldModel, VisitSystematics
    from lidar.systematic.range_walk import RangeWalkModel

    groups = {"R1": "reference", "R2": "reference", "M1": "measurement", "M2": "measurement", "M3": "measurement"}
    rows = tuple(Displacement(m, -0.001, 1e-4, 0.0, 0.0) for m in ("M1", "M2")) + \
        (Displacement("M3", float("nan"), float("nan"), float("nan"), float("nan"), ("missing",)),)
    result = EpochDisplacements(rows, ("R1", "R2"), (), np.zeros(3), np.zeros(3), "auto")

    def model(**left):
        return FieldModel("b", RangeWalkModel(), {k.replace("_", "#"): VisitSystematics(k, left_out=v)
                                                  for k, v in left.items()})

    def flags(m, **kw):
        out = with_field_misfits(m, kw.get("setups", (1,)), (1,), "e", "b", groups, result)
        return {d.reflector: [f for f in d.flags if code(f) == FLAG_FIELD_MISFIT] for d in out.displacements}

    assert flags(model()) == {"M1": [], "M2": [], "M3": []}
    got = flags(model(e=("M1",)))
    assert len(got["M1"]) == 1 and "M1" in got["M1"][0] and got["M2"] == [] and got["M3"] == []
    got = flags(model(b=("M2",)))  # the baseline's sighting: said so, on M2's row only
    assert got["M1"] == [] and "(in the baseline b)" in got["M2"][0]
    got = flags(model(e_2=("R1",)), setups=(1, 2))  # a reference target of set-up 2: every row with a value
    assert all("reference target R1" in got[m][0] for m in ("M1", "M2")) and got["M3"] == []

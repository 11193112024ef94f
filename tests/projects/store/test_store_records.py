"""The store hands out typed records, and displacement histories group them the same way for every reader."""
from __future__ import annotations

import dataclasses
import datetime as dt

import numpy as np
import pytest

from projects.store.campaign import Campaign
from projects.store.history import histories, histories_from_records
from projects.store.limits import Limit
from projects.store.records import DisplacementRecord, Epoch, Reflector, ScanFile, StoredPlan


def _rec(epoch, day, rid, d_m, s_m, flags=(), epoch_flags=()):
    return DisplacementRecord(epoch, f"2026-03-{day:02d}T09:00:00+00:00", rid, d_m, s_m, tuple(flags),
                              tuple(epoch_flags), "e1")


def test_history_groups_scales_and_keeps_gaps():
    recs = [_rec("e1", 2, "M1", 0.0, 0.0), _rec("e1", 2, "M2", 0.0, 0.0),
            _rec("e2", 9, "M1", -0.0012, 0.0001, ("clipped_by_window",)), _rec("e2", 9, "M2", None, None, ("missing",)),
            _rec("e3", 16, "M1", -0.0020, 0.0002), _rec("e3", 16, "M2", -0.0031, 0.0003)]
    lim = Limit(5.0, 10.0, "fixed:5,10")
    h = histories_from_records(recs, {"M1": lim})
    assert list(h) == ["M1", "M2"]
    m1, m2 = h["M1"], h["M2"]
    assert m1.epochs == ("e1", "e2", "e3") and m1.limit is lim and m2.limit is None
    np.testing.assert_allclose(m1.displacement_mm, [0.0, -1.2, -2.0])
    np.testing.assert_allclose(m1.sigma_mm, [0.0, 0.1, 0.2])
    assert m1.flagged.tolist() == [False, True, False]
    assert np.isnan(m2.displacement_mm[1]) and np.isnan(m2.sigma_mm[1])  # a gap stays a gap, never 0
    assert m2.measured().epochs == ("e1", "e3")
    assert m1.time_ns[1] - m1.time_ns[0] == 7 * 86_400 * 10**9
    assert m1.times[0].tzinfo is not None
    assert len(m1.thinned(2)) == 2 and m1.thinned(10) is m1
    only = histories_from_records(recs, targets=["M2"])
    assert list(only) == ["M2"]


def test_records_are_frozen_and_store_returns_them(processed):
    with Campaign.open(processed, writable=False) as c:
        epochs = c.epochs()
        assert all(isinstance(e, Epoch) for e in epochs)
        assert [e.label for e in epochs] == sorted(e.label for e in epochs)
        e = c.epoch(epochs[0].label)
        assert e.when == dt.datetime.fromisoformat(e.datetime) and e.date == e.datetime[:10]
        with pytest.raises(dataclasses.FrozenInstanceError):
            e.label = "x"
        files = c.files(e.label)
        assert files and all(isinstance(f, ScanFile) for f in files)
        assert c.path_of(files[0]).is_file()
        refl = c.reflectors()
        assert all(isinstance(r, Reflector) for r in refl)
        assert refl[0].is_reference  # reference targets first
        layout = c.layout()
        assert set(layout.ids) == {r.id for r in refl if not r.retired}
        stored = c.stored_plan(e.label)
        assert isinstance(stored, StoredPlan) and stored.plan.rois and stored.inputs_hash
        assert c.plan(e.label).to_json()["rois"] == stored.plan.to_json()["rois"]
        assert "detections" in stored.identification
        assert c.result(e.label).stage == "measured"
        ds = c.displacement_set(epochs[-1].label)
        assert ds.normal_socs.shape == (3,) and isinstance(ds.flags, tuple)
        assert all(isinstance(x.moved, bool) for x in c.reference_checks(epochs[-1].label))
        log = c.log()
        assert log[0].action == "init" and isinstance(log[0].details, dict)
        hist = histories(c)
        recs = c.displacements()
        assert set(hist) == {r.reflector for r in recs}
        last = recs[-1]
        h = hist[last.reflector]
        assert h.epochs[-1] == last.epoch
        if last.displacement_m is not None:
            assert h.displacement_mm[-1] == pytest.approx(last.displacement_m * 1000)


def test_last_displacement_is_the_latest_value_up_to_an_epoch(processed):
    with Campaign.open(processed, writable=False) as c:
        labels = [e.label for e in c.epochs()]
        rid = next(r.reflector for r in c.displacements() if r.displacement_m is not None and r.epoch == labels[-1])
        got = c.last_displacement(rid, at_or_before=labels[1])
        assert got is not None and got.epoch == labels[1] and got.reflector == rid
        assert c.last_displacement("no-such-target", at_or_before=labels[-1]) is None


def test_no_sql_outside_the_store():
    """Only the store (projects/store/) talks SQL; everyone else gets records."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[3]
    offenders = []
    for pkg in ("app", "projects"):
        for path in sorted((root / pkg).rglob("*.py")):
            rel = path.relative_to(root).as_posix()
            if rel.startswith("projects/store/"):
                continue
            text = path.read_text()
            if re.search(r"\.execute\(|\bc\.conn\b|\bsqlite3\b|\.plan_row\(|json\.loads\(\w+\[\"json\"\]", text):
                offenders.append(rel)
    assert not offenders, f"SQL or stored rows outside the store: {offenders}"

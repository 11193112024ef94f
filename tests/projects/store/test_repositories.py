"""The composed store: a campaign core with small repositories hanging off it, and one-read epoch inputs."""
from __future__ import annotations

import inspect
import io
from pathlib import Path

import numpy as np
import pytest

from lidar.layout import read_layout_csv
from projects.store import repositories
from projects.store.campaign import Campaign
from projects.store.errors import DuplicateImportError, InputError
from projects.store.records import (
    ComparisonRecord,
    CrossvalRecord,
    EpochInputs,
    EventRecord,
    PredictionRecord,
    SeriesRecord,
)


@pytest.fixture
def fresh(field_copy, tmp_path):
    with Campaign.create(tmp_path / "camp", name="Repos", layout=read_layout_csv(field_copy / "layout.csv")) as c:
        c.add_epoch("e1", "2026-03-02T09:00", field_copy / "v0" / "coarse.laz")
    return tmp_path / "camp"


def test_the_campaign_is_composed_not_mixed():
    assert Campaign.__mro__ == (Campaign, object)
    store = Path(repositories.__file__).parent
    for path in store.glob("*.py"):
        assert "NotImplementedError" not in path.read_text(), f"{path.name} has a stub"
    names = [n for n, v in vars(Campaign).items() if inspect.isfunction(v) or isinstance(v, (property, classmethod))]
    assert not {"series_arrays", "insert_event", "crossval_summaries", "comparison_summaries"} & set(names)


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def test_repositories_hand_out_records(fresh, tmp_path):
    src = tmp_path / "cam.csv"
    src.write_text("time,mm\n2026-03-02T09:00,0.1\n")
    with Campaign.open(fresh) as c:
        assert isinstance(c.series, repositories.SeriesRepository)
        path, name = c.series.check_new("camera_series", src, None, "a camera series")
        assert name == "cam"
        sha = c.series.checksum_if_new("camera_series", path)
        arrays = _npz(time_ns=np.array([1], np.int64), value_mm=np.array([0.1]))

        def record(conn, rel):
            c.series.insert(conn, "camera_series", name=name, reflector="M1", sha256=sha, stored_path=rel,
                            original_path=str(path), options={"column": "mm"}, summary={"rows": 1}, arrays=arrays)
        rel = c.import_file(path, sha, "camera", record)
        (rec,) = c.series.records("camera_series")
        assert isinstance(rec, SeriesRecord) and rec.stored_path == rel and rec.kind == "camera"
        assert rec.reflector == "M1" and rec.options == {"column": "mm"}
        assert c.series.arrays("camera_series", "cam") == arrays
        assert c.series.records("env_series") == []
        with pytest.raises(InputError, match="already in the campaign"):
            c.series.check_new("camera_series", src, None, "a camera series")
        with pytest.raises(DuplicateImportError):
            c.series.checksum_if_new("camera_series", src)
        with pytest.raises(ValueError, match="not a series table"):
            c.series.records("files")

        event_id = c.events.add("2026-03-03T00:00:00+00:00", "load", "ballast", 12.0)
        (ev,) = c.events.all()
        assert isinstance(ev, EventRecord) and ev.id == event_id and ev.load_kn_m == 12.0

        c.crossvals.save("cam", {"series": "cam", "n_pairs": 1}, {"series": "cam"})
        (cv,) = c.crossvals.all()
        assert isinstance(cv, CrossvalRecord) and cv.summary["n_pairs"] == 1

        c.comparisons.save({"from": "e1", "to": "e1", "method": "c2c", "version": 1})
        (cmp,) = c.comparisons.all()
        assert isinstance(cmp, ComparisonRecord) and (cmp.from_epoch, cmp.method) == ("e1", "c2c")

        with c.transaction() as conn:
            c.predictions.put(conn, "M1", sha256="ab" * 32, stored_path="prediction/x.csv", original_path="/x.csv",
                              options={"offset_mm": 0.0}, arrays=arrays)
        (pr,) = c.predictions.all()
        assert isinstance(pr, PredictionRecord) and pr.sha256 == "ab" * 32 and pr.arrays == arrays
        actions = [e.action for e in c.log()]
        assert {"event-add", "crossval", "compare"} <= set(actions)


def test_epoch_inputs_in_one_read_match_the_single_calls(processed):
    with Campaign.open(processed, writable=False) as c:
        label = c.epochs()[1].label
        statements: list[str] = []
        c.conn.set_trace_callback(statements.append)
        inp = c.epoch_inputs(label)
        c.conn.set_trace_callback(None)
        assert statements[0] == "BEGIN" and statements[-1] == "COMMIT"
        assert "BEGIN" not in statements[1:-1]  # every query inside one read transaction
        assert isinstance(inp, EpochInputs) and inp.label == label
        assert inp.epoch == c.epoch(label)
        assert list(inp.coarse) == c.files(label, "coarse") and list(inp.fine) == c.files(label, "fine")
        assert inp.plan is not None and inp.plan.plan_json == c.stored_plan(label).plan_json
        assert inp.result == c.result(label)
        assert inp.layout.to_rows() == c.layout(inp.epoch.datetime).to_rows()
        assert inp.profile.to_dict() == c.profile_for(label).to_dict()
        assert inp.settings == c.settings()
        assert c.epoch_inputs(label, plan=False).plan is None
        with pytest.raises(InputError, match="no epoch 'nope'"):
            c.epoch_inputs("nope")


def test_stage1_job_reads_the_store_once(processed):
    from projects.processing.stages import measure_inputs, parameters, plan_inputs, stage1_job

    with Campaign.open(processed, writable=False) as c:
        label = c.epochs()[0].label
        statements: list[str] = []
        c.conn.set_trace_callback(statements.append)
        job = stage1_job(c, label)
        c.conn.set_trace_callback(None)
        assert statements.count("BEGIN") == 1 and statements[0] == "BEGIN" and statements[-1] == "COMMIT"
        params = parameters(c)
        h, layout = plan_inputs(c, label, params)
        assert job.plan_hash == h and job.measure_hash == measure_inputs(c, label, params)
        assert job.stored_plan == c.stored_plan(label).plan_json  # unchanged inputs: the plan is reused
        assert job.fine_paths == tuple(str(c.path_of(f)) for f in c.files(label, "fine"))
        assert job.layout.to_rows() == layout.to_rows()

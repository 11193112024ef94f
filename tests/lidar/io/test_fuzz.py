"""Fuzz suite: damaged files of every format are refused cleanly, within memory and time limits.

Each case runs in a worker process limited to 3 GiB of address space and 10 s;
the outcome must be a clean read or one ScanFormatError line naming the file
(never another exception, a memory error, a hang or a crash). A sample of the
cases also goes through ``bridgesurvey add-epoch``, which must refuse them
with one line and leave the campaign byte-identical.
"""
from __future__ import annotations

import numpy as np
import pytest

from app.cli.main import main
from tests.lidar.io.fuzz_cases import build_cases
from tests.lidar.io.fuzz_runner import run_cases

pytestmark = pytest.mark.fuzz


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz")
    (folder / "samples").mkdir()
    out = []
    for c in build_cases(folder / "samples"):
        path = folder / f"{c.name}{c.suffix}"
        path.write_bytes(c.blob)
        out.append((c.name, path))
    return out


def _report(results):
    return "\n".join(f"{r.outcome} {r.name}: {r.message}" for r in results if r.outcome not in ("ok", "refused"))


def test_every_damaged_file_is_read_or_refused_in_one_line(cases):
    assert len(cases) >= 300
    results = run_cases([(name, {"path": str(path)}) for name, path in cases])
    assert len(results) == len(cases)
    assert _report(results) == ""
    refused = sum(r.outcome == "refused" for r in results)
    assert refused > len(cases) / 2  # the mutations do damage: most must be refused
    # every format family has refusals (the suite cannot pass by reading nothing)
    for family in ("las", "laz", "e57", "ply", "pcd", "ptx", "xyz", "pts", "lasf"):
        assert any(r.outcome == "refused" and r.name.startswith(family) for r in results), family


@pytest.mark.parametrize("mode", ["header", "stats"])
def test_info_describes_or_refuses_every_damaged_file_in_one_line(cases, mode):
    """``info`` (header speed and --stats) reads its own way: chunks, blocks, memory-mapped records."""
    results = run_cases([(name, {"path": str(path), "info": mode}) for name, path in cases])
    assert len(results) == len(cases)
    assert _report(results) == ""
    assert sum(r.outcome == "refused" for r in results) > len(cases) / 3


def test_reported_attacks_are_refused_quickly(cases):
    names = [n for n, _ in cases if n.startswith("lasf-random") or n in
             ("las-field100-max", "las12-field107-max", "las-field131-0", "las-field131-nan", "e57-xml-count-huge")]
    results = run_cases([(n, {"path": str(p)}) for n, p in cases if n in names], workers=1, as_limit=1 << 30,
                        case_seconds=5.0)
    assert {r.name for r in results} == set(names)
    assert all(r.outcome == "refused" for r in results), _report(results)
    assert max(r.seconds for r in results) < 2.0


def test_add_epoch_refuses_damaged_files_and_leaves_the_campaign_identical(cases, tmp_path, capsys):
    camp = tmp_path / "camp"
    layout = tmp_path / "layout.csv"
    layout.write_text("id,group,x,y,z\nR1,reference,0,0,0\nR2,reference,0,1,2\nR3,reference,40,0,0\n"
                      "M1,measurement,15,0,5\nM2,measurement,20,0,5\nM3,measurement,25,1,5\n")
    assert main(["init", str(camp), "--name", "Fuzz", "--layout", str(layout)]) == 0
    rng = np.random.default_rng(5)
    pick = [cases[k] for k in sorted(rng.choice(len(cases), 40, replace=False))]
    pick += [(n, p) for n, p in cases if n.startswith("lasf-random")]
    reqs = [(n, {"path": str(p), "campaign": str(camp), "date": f"2026-{1 + k // 28:02d}-{1 + k % 28:02d}T10:00"})
            for k, (n, p) in enumerate(pick)]
    results = run_cases(reqs, workers=1)
    assert _report(results) == ""
    refused = [r for r in results if r.outcome == "refused"]
    assert len(refused) >= 20
    assert all(r.unchanged for r in refused), [r.name for r in refused if not r.unchanged]

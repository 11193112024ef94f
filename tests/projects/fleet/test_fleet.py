"""Many bridges: fleet status and report, and fleet processing on real Dask clusters (processes, an
external scheduler, a worker killed mid-task, two runs at once)."""
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from projects.fleet.status import find_campaigns, fleet_status
from projects.processing.stages import process, set_parameter
from projects.store.campaign import Campaign

pytest.importorskip("distributed")


def _cli(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


def _stale_copy(processed, dst: Path) -> Path:
    """A copy of the processed campaign whose three epochs need stage 1 again (identical plans)."""
    shutil.copytree(processed, dst, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    with Campaign.open(dst) as c:
        set_parameter(c, "identification_tolerance_m", "0.16")
    return dst


def _tables(folder: Path):
    with Campaign.open(folder, writable=False) as c:
        rows = c.displacements()
        cents = {e.label: {k: (v.found, tuple(v.xyz_socs), v.n_points) for k, v in c.centroids(e.label).items()}
                 for e in c.epochs()}
    return rows, cents


@pytest.fixture(scope="module")
def serial_reference(processed, tmp_path_factory):
    """The stale copy brought up to date by plain 'process', campaign by campaign."""
    ref = _stale_copy(processed, tmp_path_factory.mktemp("serial") / "ref")
    with Campaign.open(ref) as c:
        process(c)
    return _tables(ref)


@pytest.fixture
def fleet(processed, tmp_path):
    root = tmp_path / "fleet"
    (root / "north").mkdir(parents=True)
    _stale_copy(processed, root / "north" / "bridge-a")
    _stale_copy(processed, root / "bridge-b")
    return root


def test_find_campaigns_in_folders_and_fleet_files(fleet, tmp_path):
    found = find_campaigns([fleet])
    assert [p.name for p in found] == ["bridge-b", "bridge-a"] or sorted(p.name for p in found) == ["bridge-a", "bridge-b"]
    listing = tmp_path / "fleet.txt"
    listing.write_text("# our bridges\nfleet/north\n\nfleet/bridge-b  # the river one\n")
    assert sorted(p.name for p in find_campaigns([listing])) == ["bridge-a", "bridge-b"]
    r = _cli("fleet", "status", tmp_path / "nowhere")
    assert r.returncode == 1 and "no such folder" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_fleet_status_follows_a_linked_campaign_once(processed, tmp_path):
    """A bridge's folder kept on another disk and linked into the fleet folder is a bridge (issue 41 item 7)."""
    elsewhere = tmp_path / "other-disk" / "bridge-c"
    shutil.copytree(processed, elsewhere, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    root = tmp_path / "fleet"
    root.mkdir()
    (root / "bridge-c").symlink_to(elsewhere, target_is_directory=True)
    (root / "loop").symlink_to(root, target_is_directory=True)  # a link back up: walked once, no endless walk
    assert [p.name for p in find_campaigns([root])] == ["bridge-c"]
    r = _cli("fleet", "status", root, "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["overview"]["bridges"] == 1 and doc["bridges"][0]["epochs"] == 3


def test_fleet_status_and_report_list_every_bridge_and_the_unreadable_one(fleet, tmp_path):
    broken = fleet / "broken"
    broken.mkdir()
    (broken / "campaign.sqlite").write_bytes(b"not a database at all" * 10)
    status = fleet_status([fleet])
    names = {Path(b["folder"]).name: b for b in status["bridges"]}
    assert set(names) == {"bridge-a", "bridge-b", "broken"}
    assert names["broken"]["error"] and status["overview"]["unreadable"] == 1
    a = names["bridge-a"]
    assert a["epochs"] == 3 and a["last_epoch"] == "2026-03-16" and a["work_left"] == 3
    assert a["state"] in ("ok", "warning", "alarm") and a["worst_target"].startswith("M")
    r = _cli("fleet", "status", fleet, "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["overview"]["bridges"] == 3
    pdf = tmp_path / "fleet.pdf"
    r = _cli("fleet", "report", fleet, "--out", pdf)
    assert r.returncode == 0 and pdf.read_bytes().startswith(b"%PDF")
    if shutil.which("pdftotext"):
        text = subprocess.run(["pdftotext", "-layout", str(pdf), "-"], capture_output=True, text=True).stdout
        assert "bridge-a" in text and "unreadable" in text


def test_fleet_process_on_a_local_cluster_gives_the_same_tables(fleet, serial_reference):
    r = _cli("fleet", "process", fleet, "--workers", "2", "--json")
    assert r.returncode == 0, r.stderr
    run = json.loads(r.stdout)
    assert run["tasks"] == 6 and run["failed"] == 0 and "LocalCluster of 2 worker processes" in run["cluster"]
    for folder in find_campaigns([fleet]):
        assert _tables(folder) == serial_reference
    r = _cli("fleet", "process", fleet, "--workers", "2", "--json")  # nothing left to do
    assert r.returncode == 0 and json.loads(r.stdout)["tasks"] == 0


def test_fleet_process_on_an_external_scheduler_with_a_worker(fleet, serial_reference, tmp_path):
    dask = Path(sys.executable).with_name("dask")
    sched_file = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    sched = subprocess.Popen([str(dask), "scheduler", "--scheduler-file", str(sched_file), "--port", "0",
                              "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    worker = None
    try:
        for _ in range(300):
            if sched_file.exists() and sched_file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        worker = subprocess.Popen([str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                   "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
        r = _cli("fleet", "process", fleet, "--scheduler", address, "--json")
        assert r.returncode == 0, r.stderr
        assert json.loads(r.stdout)["cluster"] == f"scheduler {address}"
        for folder in find_campaigns([fleet]):
            assert _tables(folder) == serial_reference
    finally:
        for p in (worker, sched):
            if p is not None:
                p.terminate()
                p.wait(timeout=30)
    r = _cli("fleet", "process", fleet, "--scheduler", "tcp://127.0.0.1:9", "--json")  # nobody there
    assert r.returncode == 1 and "cannot reach the Dask scheduler" in r.stderr


def test_a_worker_killed_mid_task_loses_nothing(fleet, serial_reference):
    from distributed import Client, LocalCluster

    from projects.fleet.process import fleet_process

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      scheduler_kwargs={"dashboard": False}) as cluster, Client(cluster) as client:
        out = {}
        t = threading.Thread(target=lambda: out.setdefault("run", fleet_process([fleet], scheduler=cluster.scheduler_address)))
        t.start()
        killed = []
        deadline = time.time() + 120
        while not killed and time.time() < deadline:
            busy = {w for w, tasks in client.processing().items() if tasks}
            if busy:
                pids = client.run(os.getpid, workers=list(busy))
                for pid in pids.values():
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
            time.sleep(0.05)
        t.join(timeout=600)
        assert killed, "no task was seen running"
        run = out["run"]
        assert run.failed == 0 and run.tasks == 6
        assert any(n.startswith("worker lost, task retried: epoch ") for n in run.notes), run.notes
    for folder in find_campaigns([fleet]):
        assert _tables(folder) == serial_reference


def test_two_fleet_runs_at_once_on_overlapping_folders(fleet, processed, serial_reference, tmp_path):
    third = _stale_copy(processed, tmp_path / "other" / "bridge-c")
    a = subprocess.Popen([sys.executable, "-m", "app.cli.main", "fleet", "process", str(fleet), "--workers", "1",
                          "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(1.0)
    b = _cli("fleet", "process", str(fleet / "bridge-b"), str(third.parent), "--workers", "1", "--json")
    out_a, err_a = a.communicate(timeout=600)
    assert a.returncode in (0, 3), err_a
    assert b.returncode in (0, 3), b.stderr
    run_b = json.loads(b.stdout)
    skipped = [c for c in run_b["campaigns"] if c["skipped"]]
    assert all("in use" in c["skipped"] for c in skipped)  # the overlap waits for nobody: skipped cleanly
    for folder in find_campaigns([fleet, third.parent]):
        assert _tables(folder) == serial_reference

"""A fleet over a network is not an open door (issue 44): a tls:// scheduler with the cluster's certificates,
refusals in one line without them, and a warning for a plain tcp:// scheduler on another machine."""
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from common.errors import InputError
from projects.fleet.process import TlsFiles, scheduler_security, scheduler_warning
from tests.projects.fleet.test_fleet import _cli, _stale_copy, _tables, serial_reference  # noqa: F401 (fixture)

pytest.importorskip("distributed")
pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl to make test certificates")


def _certificates(folder: Path) -> TlsFiles:
    """A certificate authority and one certificate (for 127.0.0.1 and localhost) signed by it, for two days."""
    def run(*args):
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)

    run("req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", "ca.key", "-out", "ca.pem", "-days", "2",
        "-subj", "/CN=bridgesurvey-test-ca")
    run("req", "-newkey", "rsa:2048", "-nodes", "-keyout", "key.pem", "-out", "req.csr", "-subj", "/CN=localhost")
    (folder / "san.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    run("x509", "-req", "-in", "req.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial", "-out", "cert.pem",
        "-days", "2", "-extfile", "san.cnf")
    return TlsFiles(str(folder / "ca.pem"), str(folder / "cert.pem"), str(folder / "key.pem"))


def test_plain_schedulers_on_other_machines_are_warned_about():
    assert scheduler_warning("tcp://127.0.0.1:8786") is None and scheduler_warning("localhost:8786") is None
    assert scheduler_warning("tls://10.0.0.7:8786") is None
    line = scheduler_warning("tcp://10.0.0.7:8786")
    assert line and "runs whatever" in line and "tls://" in line and "\n" not in line


def test_tls_needs_all_three_certificates(tmp_path, monkeypatch):
    for key in [k for k in os.environ if k.startswith("DASK_")]:
        monkeypatch.delenv(key)
    import dask

    with dask.config.set({"distributed.comm.tls.ca-file": None, "distributed.comm.tls.client.cert": None,
                          "distributed.comm.tls.client.key": None}):
        with pytest.raises(InputError, match="needs the cluster's certificates"):
            scheduler_security("tls://127.0.0.1:8786")
    with pytest.raises(InputError, match="--tls-key is missing"):
        scheduler_security("tls://127.0.0.1:8786", TlsFiles(str(tmp_path / "a"), str(tmp_path / "b"), ""))
    with pytest.raises(InputError, match="no such file"):
        scheduler_security("tls://127.0.0.1:8786", TlsFiles(*(str(tmp_path / n) for n in ("a", "b", "c"))))
    with pytest.raises(InputError, match="go with a tls:// scheduler"):
        scheduler_security("tcp://127.0.0.1:8786", TlsFiles("a", "b", "c"))


def test_fleet_process_on_a_tls_scheduler(processed, serial_reference, tmp_path):  # noqa: F811 (fixture)
    fleet = tmp_path / "fleet"
    fleet.mkdir()
    _stale_copy(processed, fleet / "bridge")
    tls = _certificates(tmp_path)
    certs = ["--tls-ca-file", tls.ca_file, "--tls-cert", tls.cert, "--tls-key", tls.key]
    dask = Path(sys.executable).with_name("dask")
    sched_file = tmp_path / "scheduler.json"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    sched = subprocess.Popen([str(dask), "scheduler", "--protocol", "tls", "--host", "127.0.0.1", "--port", "0",
                              "--scheduler-file", str(sched_file), "--no-dashboard", *certs],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    worker = None
    try:
        for _ in range(300):
            if sched_file.exists() and sched_file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tls://")
        worker = subprocess.Popen([str(dask), "worker", address, "--nworkers", "1", "--nthreads", "1",
                                   "--no-dashboard", *certs], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  env=env)
        r = _cli("fleet", "process", fleet, "--scheduler", address, "--json")  # no certificates: refused
        assert r.returncode == 1 and "needs the cluster's certificates" in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1
        r = _cli("fleet", "process", fleet, "--scheduler", address, "--json", *certs)
        assert r.returncode == 0, r.stderr
        run = json.loads(r.stdout)
        assert run["cluster"] == f"scheduler {address}" and run["tasks"] == 3 and run["failed"] == 0
        assert _tables(fleet / "bridge") == serial_reference
    finally:
        for p in (worker, sched):
            if p is not None:
                p.terminate()
                p.wait(timeout=30)

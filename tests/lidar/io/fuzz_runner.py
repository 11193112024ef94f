"""Run fuzz cases in worker processes with a memory limit and a time limit per case.

``python -m tests.lidar.io.fuzz_runner`` runs the whole suite standalone and
prints every case that was not cleanly refused or read, and the slowest ones.
"""
from __future__ import annotations

import json
import os
import selectors
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
#: Seconds one case may take before the worker is killed and the case fails.
CASE_SECONDS = 10.0


@dataclass
class Result:
    name: str
    outcome: str  # ok | refused | bug | timeout | crash
    message: str
    seconds: float
    unchanged: bool | None = None


class Worker:
    def __init__(self, as_limit: int):
        env = dict(os.environ, FUZZ_AS_LIMIT=str(as_limit), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                   RAYON_NUM_THREADS="1", PYTHONPATH=str(ROOT))
        self.proc = subprocess.Popen([sys.executable, "-m", "tests.lidar.io.fuzz_worker"], cwd=ROOT, env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, bufsize=1)
        self._read(120.0)

    def _read(self, timeout: float):
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        if not sel.select(timeout):
            return None
        line = self.proc.stdout.readline()
        return json.loads(line) if line else {"outcome": "crash", "message": f"worker died ({self.proc.poll()})"}

    def run(self, req: dict, timeout: float) -> dict | None:
        self.proc.stdin.write(json.dumps(req) + "\n")
        self.proc.stdin.flush()
        return self._read(timeout)

    def kill(self):
        self.proc.kill()
        self.proc.wait()


def run_cases(requests: list[tuple[str, dict]], *, workers: int = 2, as_limit: int = 3 << 30,
              case_seconds: float = CASE_SECONDS) -> list[Result]:
    """Run ``(name, request)`` pairs; a worker that times out or dies is replaced."""
    results: list[Result] = []
    lock = threading.Lock()
    queue = list(requests)

    def loop():
        w = Worker(as_limit)
        while True:
            with lock:
                if not queue:
                    break
                name, req = queue.pop(0)
            t0 = time.perf_counter()
            res = w.run(req, case_seconds)
            dt = time.perf_counter() - t0
            if res is None:
                w.kill()
                res = {"outcome": "timeout", "message": f"no answer within {case_seconds:.0f} s"}
                w = Worker(as_limit)
            elif res.get("outcome") == "crash":
                w.kill()
                w = Worker(as_limit)
            with lock:
                results.append(Result(name, res["outcome"], res.get("message", ""), dt, res.get("unchanged")))
        w.kill()

    threads = [threading.Thread(target=loop) for _ in range(workers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return sorted(results, key=lambda r: r.name)


def main() -> None:
    from tests.lidar.io.fuzz_cases import build_cases

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "samples").mkdir()
        cases = build_cases(tmp / "samples")
        reqs = []
        for c in cases:
            p = tmp / f"{c.name}{c.suffix}"
            p.write_bytes(c.blob)
            reqs.append((c.name, {"path": str(p)}))
        t0 = time.perf_counter()
        results = run_cases(reqs)
        total = time.perf_counter() - t0
    bad = [r for r in results if r.outcome not in ("ok", "refused")]
    for r in bad:
        print(f"{r.outcome:8s} {r.name}: {r.message}")
    counts = {k: sum(r.outcome == k for r in results) for k in ("ok", "refused", "bug", "timeout", "crash")}
    print(f"{len(results)} cases in {total:.1f} s: {counts}")
    for r in sorted(results, key=lambda r: -r.seconds)[:5]:
        print(f"slowest: {r.seconds:.3f} s {r.name} ({r.outcome})")


if __name__ == "__main__":
    main()

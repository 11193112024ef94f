"""Fleet processing (issue 16): serial against a LocalCluster and against a separate scheduler and workers.

A fleet of 4 simulated campaigns (the demo builder, 6 weekly visits each, different seeds) is made stale
by a stage-1 parameter change, copied, and brought up to date three ways:

* serial: ``process`` campaign after campaign in this process (the baseline);
* ``fleet process --workers 2``: a LocalCluster of 2 worker processes;
* ``fleet process --scheduler``: ``dask scheduler`` and two ``dask worker`` processes started beforehand.

Times are wall-clock for the whole command (start-up included); results are checked identical.
Usage: ``./run bench bench_fleet [CAMPAIGNS] [WEEKS]`` (``--small``: 2 campaigns x 2 epochs of
a 0.12 degree scan, the second a copy of the first).
"""
from __future__ import annotations

import dataclasses
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _harness import figures, small_mode  # noqa: E402
from bench_campaign import build_campaign  # noqa: E402

from projects.demo import build_demo  # noqa: E402
from projects.processing.stages import process, set_parameter  # noqa: E402
from projects.store.campaign import Campaign  # noqa: E402


def cli(*args):
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, args)], cwd=ROOT, capture_output=True,
                       text=True)
    if r.returncode != 0:
        raise SystemExit(f"failed: {' '.join(map(str, args))}\n{r.stderr}")
    return time.perf_counter() - t0, r.stdout


def tables(root: Path):
    out = {}
    for db in sorted(root.rglob("campaign.sqlite")):
        with Campaign.open(db.parent, writable=False) as c:
            out[db.parent.name] = c.displacements()
    return out


#: Numbers that differ by less than this (metres, ppm, ...) are the same result computed in another order.
ROUNDING = 1e-9


def _numbers_differ(a, b, path: str, out: list) -> None:
    """Collect where ``a`` and ``b`` differ: (path, absolute difference or None where not numbers)."""
    if isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys():
        for k in a:
            _numbers_differ(a[k], b[k], f"{path}.{k}", out)
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b):
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _numbers_differ(x, y, f"{path}[{k}]", out)
    elif isinstance(a, float) and isinstance(b, float):
        if a != b and not (a != a and b != b):
            out.append((path, abs(a - b)))
    elif a != b:
        out.append((path, None))


def same_tables(got: dict, ref: dict, what: str) -> float:
    """The largest numeric difference between two fleets' displacement tables (0.0: identical); exits naming the
    first differences when anything but a last-digit rounding differs."""
    diffs: list = []
    if got.keys() != ref.keys():
        diffs.append(("campaigns", None))
    for name in ref:
        a, b = got.get(name, []), ref[name]
        if len(a) != len(b):
            diffs.append((f"{name}: rows", None))
            continue
        for x, y in zip(a, b, strict=True):
            _numbers_differ(dataclasses.asdict(x), dataclasses.asdict(y), f"{name} {y.epoch} {y.reflector}", diffs)
    bad = [d for d in diffs if d[1] is None or d[1] > ROUNDING]
    if bad:
        raise SystemExit(f"{what} results differ from serial processing: "
                         + "; ".join(p if d is None else f"{p} by {d:.3g}" for p, d in bad[:8]))
    return max((d for _, d in diffs), default=0.0)


def main(n_campaigns: int = 4, weeks: int = 6, *, copies: bool = False):
    """``copies`` (the small mode): one campaign of ``weeks`` epochs of one visit scanned at 0.12 degrees
    (``bench_campaign``'s), copied for the others: the processing is the same, the demo builder's visits take
    minutes."""
    work = Path(tempfile.mkdtemp(prefix="bench-fleet-"))
    try:
        src = work / "src"
        t0 = time.perf_counter()
        for k in range(n_campaigns):
            if copies and not k:
                camp, _ = build_campaign(work / "one", weeks, coarse_step_deg=0.12)
                shutil.copytree(camp, src / "bridge-1", ignore=shutil.ignore_patterns(".lock"))
            elif copies:
                shutil.copytree(src / "bridge-1", src / f"bridge-{k + 1}", ignore=shutil.ignore_patterns(".lock"))
            else:
                build_demo(src / f"bridge-{k + 1}", weeks=weeks, seed=100 + k)
            with Campaign.open(src / f"bridge-{k + 1}") as c:
                set_parameter(c, "identification_tolerance_m", "0.16")  # every epoch needs stage 1 again
        print(f"fleet of {n_campaigns} campaigns x {weeks} epochs built in {time.perf_counter() - t0:.0f} s")
        epochs = n_campaigns * weeks

        serial = work / "serial"
        shutil.copytree(src, serial)
        t0 = time.perf_counter()
        cpu0 = resource.getrusage(resource.RUSAGE_SELF)
        for db in sorted(serial.rglob("campaign.sqlite")):
            with Campaign.open(db.parent) as c:
                process(c)
        t_serial = time.perf_counter() - t0
        cpu1 = resource.getrusage(resource.RUSAGE_SELF)
        cores_used = (cpu1.ru_utime - cpu0.ru_utime + cpu1.ru_stime - cpu0.ru_stime) / t_serial
        ref = tables(serial)

        local = work / "local"
        shutil.copytree(src, local)
        t_local, _ = cli("fleet", "process", local, "--workers", "2")
        rounding = same_tables(tables(local), ref, "LocalCluster")

        ext = work / "external"
        shutil.copytree(src, ext)
        dask = Path(sys.executable).with_name("dask")
        sf = work / "scheduler.json"
        procs = [subprocess.Popen([str(dask), "scheduler", "--scheduler-file", str(sf), "--port", "0", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)]
        try:
            while not (sf.exists() and sf.stat().st_size):
                time.sleep(0.1)
            address = json.loads(sf.read_text())["address"]
            procs.append(subprocess.Popen([str(dask), "worker", address, "--nworkers", "2", "--nthreads", "1",
                                           "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                          cwd=ROOT))
            time.sleep(3.0)  # let the workers register (their start-up is not part of a run)
            t_ext, _ = cli("fleet", "process", ext, "--scheduler", address)
        finally:
            for p in procs[::-1]:
                p.terminate()
                p.wait(timeout=30)
        rounding = max(rounding, same_tables(tables(ext), ref, "external-cluster"))

        print(f"\n| mode | seconds for {epochs} epochs | per epoch | ratio to serial |")
        print("|---|---|---|---|")
        for name, t in (("serial 'process', one campaign after another", t_serial),
                        ("fleet process, LocalCluster of 2 worker processes", t_local),
                        ("fleet process, separate dask scheduler + 2 workers", t_ext)):
            print(f"| {name} | {t:.1f} | {t / epochs:.2f} | {t / t_serial:.2f} |")
        print("Displacement tables identical in all three modes." if rounding == 0.0 else
              f"Displacement tables the same in all three modes to {rounding:.1g} (rounding: sums in another order).")
        figures(campaigns=n_campaigns, epochs=epochs, displacement_rows=sum(len(t) for t in ref.values()),
                local_ratio=t_local / t_serial, external_ratio=t_ext / t_serial, largest_rounding=rounding)
        print(f"Serial processing already keeps {cores_used:.1f} of this machine's {os.cpu_count()} cores busy "
              "(multi-threaded LAZ decoding and numpy): on one machine the cluster only adds overlap; "
              "its gain is in adding machines.")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(*(tuple(int(a) for a in _args[:2]) or ((2, 2) if _small else ())), copies=_small)

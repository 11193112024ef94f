"""Two hundred bridges, one week each, on Dask (issue 44; issue 16 before it): time per bridge, the gain from one
worker to two, memory per worker, failures.

A fleet of campaigns, each a baseline and one visit a week later (coarse scans at 0.12°, planned, their fine
scans imported, not processed), is brought up to date by ``bridgesurvey fleet process``, each run on its own
copy of the unprocessed fleet: ``--subset`` bridges (default 20) three ways,

* ``--workers 1``: a LocalCluster of one worker process;
* ``--workers 2``: a LocalCluster of two;
* ``--scheduler tcp://127.0.0.1:PORT``: a ``dask scheduler`` and ``dask worker --nworkers 2`` started by the bench
  (their start-up is not timed);

then all ``--bridges`` (default 200) on the LocalCluster of two workers, followed by ``fleet status`` and
``fleet report`` over them. (An epoch task costs about 3 s of a core here: the three-way comparison over all 200
bridges would be an hour of the two cores.) Times are wall-clock for the whole command
(start-up included). Memory per worker is the largest resident size any worker process reached (sampled every
0.2 s through the process tree). Failures are the epochs ``fleet process --json`` reports failed plus the
campaigns it skipped: the issue asks for none. Every run's displacement tables must agree bridge for bridge
(to the last digits of sums taken in another order), else the bench stops.

Saving time (the simulator's work, not the product's): ``--kinds`` distinct bridges (default 4: different
set-ups, weather and deck states, seeds) are simulated and imported once; the fleet holds copies of them, each
its own campaign folder (its database copied, its scans hard-linked: a campaign never writes a scan).

Usage: ``./run bench bench_fleet [--bridges 200] [--subset 20] [--kinds 4]`` (``--small``: 4 bridges of 2 kinds,
a subset of 2).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _harness import figures, small_mode, write_figure  # noqa: E402

from lidar.layout import layout_from_model  # noqa: E402
from lidar.simulate.bridge import BridgeModel  # noqa: E402
from lidar.simulate.campaign import random_conditions  # noqa: E402
from lidar.simulate.files import simulate_coarse, simulate_fine  # noqa: E402
from lidar.simulate.setup import ScannerSetup  # noqa: E402
from projects.processing.stages import plan_epoch  # noqa: E402
from projects.store.campaign import Campaign  # noqa: E402
from projects.store.imports import SCANS_DIR  # noqa: E402

DATES = ("2026-03-02T09:00:00+00:00", "2026-03-09T09:00:00+00:00")
#: Where the scanner stands (x, y, heading: the 40 m bridge from beside it, m and degrees), moved by up to a metre
#: and 10 degrees each visit: near enough for a 0.12 degree coarse scan to find every target.
STATIONS = ((20.0, -12.0, 30.0), (14.0, -12.0, 40.0), (24.0, -15.0, 200.0), (26.0, -12.0, 20.0))
#: Numbers that differ by less than this (metres, ppm, ...) are the same result computed in another order.
ROUNDING = 1e-9


def build_kind(work: Path, k: int, seed: int = 16) -> Path:
    """One bridge's campaign: a baseline and a visit a week later, planned, fine scans imported, not processed."""
    model = BridgeModel()
    rng = np.random.default_rng(seed + k)
    layout = layout_from_model(model, noise_m=0.02, rng=np.random.default_rng(seed + 100 + k))
    camp = work / f"kind-{k + 1}"
    with Campaign.create(camp, name=f"bridge kind {k + 1}", layout=layout, span_m=model.span_m) as c:
        for v, when in enumerate(DATES):
            cond = random_conditions(model, rng, ppm=(-20, 20), max_walk_m=None, temperature_c=(-5, 25))
            x, y, heading = STATIONS[(2 * k + v) % len(STATIONS)]
            setup = ScannerSetup((x + rng.uniform(-1, 1), y + rng.uniform(-1, 1), 1.5),
                                 heading_deg=heading + rng.uniform(-10, 10))
            field = work / f"field-{k + 1}-{v}"
            coarse, _ = simulate_coarse(field, setup=setup, conditions=cond, model=model, seed=seed + 10 * k + v,
                                        coarse_step_deg=0.12)
            label = f"v{v}"
            c.add_epoch(label, when, coarse)
            plan = plan_epoch(c, label)
            fine, _ = simulate_fine(field, plan.rois, model=model)
            c.import_files(label, [fine], "fine")
            shutil.rmtree(field)
    return camp


def copy_campaign(src: Path, dst: Path) -> None:
    """A campaign folder copied: its scans hard-linked (never written), everything else copied; no lock file."""
    def one(s, d):
        if Path(SCANS_DIR) in Path(s).relative_to(src).parents and not os.path.islink(s):
            os.link(s, d)
        else:
            shutil.copy2(s, d)
    shutil.copytree(src, dst, copy_function=one, symlinks=True, ignore=shutil.ignore_patterns(".lock"))


def make_fleet(kinds: list[Path], folder: Path, bridges: int) -> Path:
    for b in range(bridges):
        copy_campaign(kinds[b % len(kinds)], folder / f"bridge-{b + 1:03d}")
    return folder


class Watch:
    """The largest resident size of each process below ``root`` (a pid) while it runs, sampled every 0.2 s."""

    def __init__(self, roots: list[int]):
        self.roots = roots
        self.peak: dict[int, tuple[str, int]] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            for r in self.roots:
                try:
                    procs = psutil.Process(r).children(recursive=True)
                except psutil.NoSuchProcess:
                    continue
                for p in procs:
                    try:
                        rss, cmd = p.memory_info().rss, " ".join(p.cmdline()[-4:])
                    except (psutil.NoSuchProcess, psutil.AccessDenied):
                        continue
                    if rss > self.peak.get(p.pid, ("", 0))[1]:
                        self.peak[p.pid] = (cmd, rss)
            self._stop.wait(0.2)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def worker_mb(self) -> float:
        """The largest worker process (a Dask worker: its command line runs the worker or spawn's main)."""
        workers = [rss for cmd, rss in self.peak.values() if "spawn" in cmd or "worker" in cmd or "forkserver" in cmd]
        return max(workers, default=0) / 2 ** 20


def cli(*args, watch_also: list[int] = ()) -> tuple[float, dict, Watch]:
    """Run ``bridgesurvey ARGS --json`` and return its wall-clock seconds, its JSON and the watch of its processes."""
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "app.cli.main", *map(str, args)], cwd=ROOT, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    watch = Watch([p.pid, *watch_also])
    out, err = p.communicate()
    dt = time.perf_counter() - t0
    watch.stop()
    if p.returncode not in (0, 3):  # 3: some epochs failed, counted below
        raise SystemExit(f"failed: {' '.join(map(str, args))}\n{err[-3000:]}")
    try:
        doc = json.loads(out) if "--json" in map(str, args) else {}
    except json.JSONDecodeError:
        raise SystemExit(f"{' '.join(map(str, args))}: no JSON on its output: {out[-500:]}") from None
    return dt, doc, watch


def failures(doc: dict) -> int:
    """Epochs failed and campaigns skipped in a ``fleet process --json`` document."""
    failed = sum(o["action"] == "failed" for c in doc["campaigns"] for o in c["outcomes"])
    return max(failed, doc["failed"]) + sum(c["skipped"] is not None for c in doc["campaigns"])


def tables(root: Path) -> dict:
    out = {}
    for db in sorted(root.rglob("campaign.sqlite")):
        with Campaign.open(db.parent, writable=False) as c:
            out[db.parent.name] = [dataclasses.asdict(r) for r in c.displacements()]
    return out


def _differ(a, b, path: str, out: list) -> None:
    if isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys():
        for k in a:
            _differ(a[k], b[k], f"{path}.{k}", out)
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) and len(a) == len(b):
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _differ(x, y, f"{path}[{k}]", out)
    elif isinstance(a, float) and isinstance(b, float):
        if a != b and not (a != a and b != b):
            out.append((path, abs(a - b)))
    elif a != b:
        out.append((path, None))


def same_tables(got: dict, ref: dict, what: str) -> float:
    """The largest numeric difference between two fleets' displacement tables; stops the bench on anything more."""
    diffs: list = []
    _differ(got, ref, "", diffs)
    bad = [d for d in diffs if d[1] is None or d[1] > ROUNDING]
    if bad:
        raise SystemExit(f"{what}: results differ from the one-worker run: "
                         + "; ".join(p if d is None else f"{p} by {d:.3g}" for p, d in bad[:8]))
    return max((d for _, d in diffs), default=0.0)


def external_cluster(work: Path, workers: int) -> tuple[list[subprocess.Popen], str]:
    dask = Path(sys.executable).with_name("dask")
    sf = work / "scheduler.json"
    procs = [subprocess.Popen([str(dask), "scheduler", "--scheduler-file", str(sf), "--host", "127.0.0.1",
                               "--port", "0", "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              cwd=ROOT)]
    deadline = time.monotonic() + 60
    while not (sf.exists() and sf.stat().st_size):
        if time.monotonic() > deadline or procs[0].poll() is not None:
            stop(procs)
            raise SystemExit("the dask scheduler did not start")
        time.sleep(0.1)
    address = json.loads(sf.read_text())["address"]
    procs.append(subprocess.Popen([str(dask), "worker", address, "--nworkers", str(workers), "--nthreads", "1",
                                   "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT))
    from distributed import Client

    with Client(address, timeout="30s") as client:  # the workers registered: their start-up is not timed
        client.wait_for_workers(workers, timeout=120)
    return procs, address


def stop(procs: list[subprocess.Popen]) -> None:
    for p in procs[::-1]:
        p.terminate()
        try:
            p.wait(timeout=30)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def process_fleet(work: Path, templates: list[Path], name: str, bridges: int, workers: int, external: bool,
                  ref: dict | None) -> tuple[dict, dict, float, Path]:
    """One ``fleet process`` run over ``bridges`` fresh copies: its row, its tables, the rounding against ``ref``."""
    fleet = make_fleet(templates, work / f"fleet-{name.split(',')[0].replace(' ', '-')}-{workers}-{bridges}", bridges)
    procs: list[subprocess.Popen] = []
    how = ["--workers", str(workers)]
    if external:
        procs, address = external_cluster(work, workers)
        how = ["--scheduler", address]
    try:
        t, doc, watch = cli("fleet", "process", fleet, *how, "--json", watch_also=[p.pid for p in procs])
    finally:
        stop(procs)
    got = tables(fleet)
    rounding = 0.0 if ref is None else same_tables(got, {k: ref[k] for k in got}, name)
    row = {"mode": name, "bridges": bridges, "workers": workers, "seconds": t, "per_bridge_s": t / bridges,
           "tasks": doc["tasks"], "failures": failures(doc), "worker_mb": watch.worker_mb(),
           "load": os.getloadavg()[0]}
    print(f"  {name}, {bridges} bridges: {t:.0f} s, {row['per_bridge_s']:.2f} s a bridge, {row['tasks']} epoch tasks, "
          f"{row['failures']} failures, largest worker {row['worker_mb']:.0f} MB, load {row['load']:.1f}", flush=True)
    return row, got, rounding, fleet


def run(work: Path, bridges: int, kinds: int, subset: int) -> tuple[list[dict], dict]:
    t0 = time.perf_counter()
    templates = [build_kind(work / "kinds", k) for k in range(kinds)]
    print(f"{kinds} bridge(s) simulated and imported in {time.perf_counter() - t0:.0f} s", flush=True)
    rows: list[dict] = []
    ref: dict | None = None
    rounding = 0.0
    for name, workers, external in (("LocalCluster", 1, False), ("LocalCluster", 2, False),
                                    ("dask scheduler + workers started beforehand", 2, True)):
        row, got, r, fleet = process_fleet(work, templates, name, subset, workers, external, ref)
        ref = got if ref is None else ref
        rounding = max(rounding, r)
        rows.append(row)
        shutil.rmtree(fleet)
    # the whole fleet: its tables against the subset's (the same bridge kinds, the same results)
    kind_ref = {f"bridge-{b + 1:03d}": ref[f"bridge-{b % len(templates) + 1:03d}"] for b in range(bridges)}
    row, _, r, fleet = process_fleet(work, templates, "LocalCluster", bridges, 2, False, kind_ref)
    rounding = max(rounding, r)
    rows.append(row)
    t_status, _, _ = cli("fleet", "status", fleet, "--json")
    t_report, _, _ = cli("fleet", "report", fleet, "--out", work / "fleet.pdf")
    extra = {"status_s": t_status, "report_s": t_report, "report_mb": (work / "fleet.pdf").stat().st_size / 1e6,
             "rounding": rounding, "rows": sum(len(v) for v in ref.values()), "bridges": bridges}
    print(f"  fleet status {t_status:.1f} s, fleet report {t_report:.1f} s ({extra['report_mb']:.2f} MB)", flush=True)
    return rows, extra


def table(rows: list[dict], extra: dict) -> str:
    one = rows[0]["seconds"]
    lines = ["| run (one week each: a baseline and a visit) | bridges | seconds | per bridge s | gain over 1 worker | "
             "epoch tasks | failures | largest worker MB | load (1 min) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        gain = f"{one / r['seconds']:.2f}×" if r["bridges"] == rows[0]["bridges"] else \
            f"{rows[0]['per_bridge_s'] / r['per_bridge_s']:.2f}× a bridge"
        lines.append(f"| {r['mode']}, {r['workers']} worker process{'es' if r['workers'] > 1 else ''} | "
                     f"{r['bridges']} | {r['seconds']:.0f} | {r['per_bridge_s']:.2f} | {gain} | {r['tasks']} | "
                     f"{r['failures']} | {r['worker_mb']:.0f} | {r['load']:.1f} |")
    same = "identical" if extra["rounding"] == 0.0 else f"the same to {extra['rounding']:.1g}"
    return ("\n".join(lines) + f"\n\n`fleet status` over the {extra['bridges']} processed bridges "
            f"{extra['status_s']:.1f} s, `fleet report` {extra['report_s']:.1f} s ({extra['report_mb']:.2f} MB); "
            f"every run's displacement tables {same} bridge for bridge.")


def main(argv: list[str]) -> int:
    small, argv = small_mode(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bridges", type=int, default=4 if small else 200)
    ap.add_argument("--kinds", type=int, default=2 if small else 4)
    ap.add_argument("--subset", type=int, default=2 if small else 20,
                    help="bridges of the three-way comparison (1 and 2 workers, an external scheduler)")
    args = ap.parse_args(argv)
    kinds = max(1, min(args.kinds, args.subset, args.bridges))
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
        rows, extra = run(Path(tmp), args.bridges, kinds, min(args.subset, args.bridges))
    text = table(rows, extra)
    print(text)
    figures(bridges=args.bridges, failures=sum(r["failures"] for r in rows),
            gain_1_to_2=rows[0]["seconds"] / rows[1]["seconds"], external_gain=rows[0]["seconds"] / rows[2]["seconds"],
            per_bridge_s_2=rows[-1]["per_bridge_s"], worker_mb_max=max(r["worker_mb"] for r in rows),
            displacement_rows=extra["rows"], largest_rounding=extra["rounding"])
    if not small:
        write_figure("bench_fleet", text, argv=argv)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

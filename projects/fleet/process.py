"""Processing many campaigns on a Dask cluster: workers compute, the campaigns' owner saves.

Every stale epoch of every campaign becomes one ``dask.distributed`` task running
:func:`projects.processing.run_stage1` on plain values (file paths, layout, parameters, scanner);
workers never open a campaign. This process holds each campaign's writer lock for the whole run and
saves each result in its own transaction as it arrives, so bridges never wait for each other and an
interrupted run keeps everything saved so far. Stage 2 (displacements, cheap) runs here once a
campaign's epochs are in.

Workers need the same BridgeSurvey installed and the campaign folders at the same paths (shared
storage). A worker that dies mid-task loses nothing: the scheduler runs the task again elsewhere
(``retries`` covers errors raised by the task itself), and the run says so ("worker lost, task retried:
epoch L of BRIDGE", :attr:`FleetRun.notes`). A campaign another process is writing (another
fleet run, the desktop application) is skipped with a message, not waited for.
"""
from __future__ import annotations

import contextlib
import logging
import os
import socket
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlsplit

from common.errors import InputError, SurveyError
from common.processes import quiet_resource_tracker
from common.progress import ProgressCallback, report
from projects.fleet.status import find_campaigns
from projects.processing.stages import (
    EpochOutcome,
    ProcessSummary,
    finish_displacements,
    run_stage1,
    save_stage1,
    stage1_jobs,
    stale_epochs,
)
from projects.store.campaign import Campaign
from projects.store.errors import CampaignLockedError

log = logging.getLogger(__name__)
TASK_RETRIES = 2


@dataclass
class CampaignRun:
    """One campaign in a fleet run: its processing summary, the tasks it sent, or why it was skipped."""

    folder: str
    name: str = ""
    skipped: str | None = None
    summary: ProcessSummary = field(default_factory=ProcessSummary)
    tasks: int = 0


@dataclass
class FleetRun:
    """A whole fleet run: every campaign, the tasks, the failures, the cluster that ran them and what it met.

    ``notes`` are one line each: a worker lost while running a task that was then retried.
    """

    campaigns: list[CampaignRun] = field(default_factory=list)
    tasks: int = 0
    failed: int = 0
    cluster: str = ""
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        return {"cluster": self.cluster, "tasks": self.tasks, "failed": self.failed, "notes": self.notes,
                "campaigns": [{"folder": r.folder, "name": r.name, "skipped": r.skipped, "tasks": r.tasks,
                               "baseline": r.summary.baseline, "displacement_epochs": r.summary.displacement_epochs,
                               "outcomes": [o.__dict__ for o in r.summary.outcomes],
                               "problems": r.summary.problems} for r in self.campaigns]}


def _task(job):
    """The worker side: stage 1 of one epoch (imported by name on the worker)."""
    return run_stage1(job)


@dataclass(frozen=True)
class TlsFiles:
    """The certificates of a ``tls://`` scheduler's cluster, PEM files.

    Attributes
    ----------
    ca_file : path
        The certificate authority that signed the cluster's certificates (the scheduler's and ours).
    cert, key : path
        This client's certificate and its private key.
    """

    ca_file: str
    cert: str
    key: str


#: Hosts a plain ``tcp://`` scheduler may have without a warning: this machine.
LOCAL_HOSTS = ("127.0.0.1", "localhost", "::1")
#: Dask's configuration keys a ``tls://`` address reads its certificates from when none are given.
DASK_TLS_KEYS = "distributed.comm.tls.ca-file, distributed.comm.tls.client.cert and distributed.comm.tls.client.key"


def scheduler_warning(address: str) -> str | None:
    """One line when ``address`` is a plain (unencrypted, unauthenticated) connection to another machine.

    A Dask scheduler runs whatever its clients send: on a network it must only accept clients that hold the
    cluster's certificates (``tls://`` with :class:`TlsFiles` or Dask's configuration).

    >>> scheduler_warning("tcp://127.0.0.1:8786") is None
    True
    >>> scheduler_warning("tcp://10.0.0.7:8786").startswith("tcp://10.0.0.7:8786 is a plain connection")
    True
    """
    parts = urlsplit(address if "://" in address else f"tcp://{address}")
    if parts.scheme != "tcp":
        return None
    host = parts.hostname or ""
    if host in LOCAL_HOSTS or host == socket.gethostname():
        return None
    return (f"{address} is a plain connection to another machine: its scheduler runs whatever any client on the "
            "network sends, and nothing is encrypted; use tls:// with the cluster's certificates (--tls-ca-file, "
            "--tls-cert, --tls-key, or Dask's configuration: see the fleet guide)")


def scheduler_security(address: str, tls: TlsFiles | None = None):
    """The ``distributed.Security`` a scheduler address needs (None for a plain one).

    ``tls://`` takes the certificates given (all three, existing files) or, without them, Dask's configuration
    (:data:`DASK_TLS_KEYS`); neither is an :class:`~common.errors.InputError` saying what to give. Certificates
    with a plain address are refused (they would not be used).
    """
    # local: dask.distributed costs 'fleet status' and 'fleet report' 0.25 s of start-up (measured)
    from distributed import Security

    scheme = urlsplit(address).scheme if "://" in address else "tcp"
    if scheme != "tls":
        if tls is not None:
            raise InputError(f"{address}: certificates go with a tls:// scheduler address; this one is {scheme}://")
        return None
    if tls is None:
        sec = Security()  # Dask's configuration (~/.config/dask/*.yaml, DASK_DISTRIBUTED__COMM__TLS__* variables)
        ca, cert, key = (getattr(sec, name, None) for name in ("tls_ca_file", "tls_client_cert", "tls_client_key"))
        if not (ca and cert):
            raise InputError(f"{address}: a tls:// scheduler needs the cluster's certificates: give --tls-ca-file, "
                             f"--tls-cert and --tls-key, or set {DASK_TLS_KEYS} in Dask's configuration")
        return Security(tls_ca_file=ca, tls_client_cert=cert, tls_client_key=key, require_encryption=True)
    files = (("--tls-ca-file", tls.ca_file), ("--tls-cert", tls.cert), ("--tls-key", tls.key))
    for what, path in files:
        if not path:
            raise InputError(f"{address}: {what} is missing: a tls:// scheduler needs --tls-ca-file, --tls-cert and "
                             "--tls-key together")
    for what, path in files:
        if not Path(path).is_file():
            raise InputError(f"{path}: no such file ({what})")
    return Security(tls_ca_file=str(tls.ca_file), tls_client_cert=str(tls.cert), tls_client_key=str(tls.key),
                    require_encryption=True)


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int | None, tls: TlsFiles | None = None):
    try:
        # local: dask.distributed costs 'fleet status' and 'fleet report' 0.25 s of start-up (measured)
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a dependency of the package
        raise InputError("fleet processing needs dask.distributed; reinstall BridgeSurvey") from None
    if scheduler:
        security = scheduler_security(scheduler, tls)
        try:
            client = Client(scheduler, timeout="20s", security=security)
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({exc}); start it with "
                             "'dask scheduler' and its workers with 'dask worker ADDRESS'") from None
        try:
            yield client, f"scheduler {scheduler}"
        finally:
            client.close()
        return
    quiet_resource_tracker()  # a tracker killed with the workers would fill stderr with stdlib tracebacks
    n = workers or max(1, min(4, os.cpu_count() or 1))
    if not log.isEnabledFor(logging.INFO):  # the cluster's own chatter only with --verbose
        for name in ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.core"):
            logging.getLogger(name).setLevel(logging.ERROR)
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           scheduler_kwargs={"dashboard": False}, silence_logs=logging.ERROR)
    client = Client(cluster)
    try:
        yield client, f"LocalCluster of {n} worker processes"
    finally:
        client.close()
        cluster.close()


def fleet_process(roots: Sequence[str | os.PathLike], *, scheduler: str | None = None,
                  workers: int | None = None, tls: TlsFiles | None = None,
                  progress: ProgressCallback | None = None) -> FleetRun:
    """Bring every campaign under ``roots`` up to date on a Dask cluster (see the module notes).

    Parameters
    ----------
    roots : sequence of folders or fleet files
    scheduler : str, optional, keyword-only
        Address of a running Dask scheduler (``tls://host:8786`` on a network, ``tcp://`` on this machine; see
        :func:`scheduler_warning`); default: a LocalCluster here.
    workers : int, optional, keyword-only
        Worker processes of the LocalCluster (default one per core, at most 4).
    tls : TlsFiles, optional, keyword-only
        The certificates of a ``tls://`` scheduler's cluster (default: Dask's configuration).
    progress : callable, optional, keyword-only
    """
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    folders = find_campaigns(roots)
    if scheduler:  # certificates checked before any campaign is opened
        scheduler_security(scheduler, tls)
    run = FleetRun()
    with contextlib.ExitStack() as stack:
        open_campaigns: dict[str, Campaign] = {}
        jobs = []
        for folder in folders:
            cr = CampaignRun(str(folder))
            run.campaigns.append(cr)
            try:
                c = stack.enter_context(Campaign.open(folder, writable=True))
            except CampaignLockedError as exc:
                cr.skipped = str(exc).splitlines()[0]
                continue
            except SurveyError as exc:
                cr.skipped = str(exc).splitlines()[0]
                continue
            cr.name = c.name
            open_campaigns[cr.folder] = c
            stale = stale_epochs(c)
            for e in c.epochs():
                if e.label in stale:
                    try:
                        for job in stage1_jobs(c, e.label):  # one task per stale set-up of the visit
                            jobs.append((cr, job))
                            cr.tasks += 1
                    except SurveyError as exc:
                        cr.summary.outcomes.append(EpochOutcome(e.label, "failed", str(exc)))
        run.tasks = len(jobs)
        if jobs or scheduler:  # a scheduler given is checked even when there is nothing to do
            client, run.cluster = stack.enter_context(_client(scheduler, workers, tls))
            if jobs:
                _run_tasks(client, jobs, open_campaigns, run, progress)
        for cr in run.campaigns:
            oc = open_campaigns.get(cr.folder)
            if oc is None:
                continue
            labels = [e.label for e in oc.epochs()]
            done = {o.epoch for o in cr.summary.outcomes}
            cr.summary.outcomes += [EpochOutcome(lab, "up-to-date") for lab in labels if lab not in done]
            finish_displacements(oc, cr.summary, labels)
    report(progress, 1.0, f"{run.tasks} epoch(s) on {len(folders)} campaign(s)")
    return run


def _run_tasks(client, jobs, open_campaigns, run: FleetRun, progress) -> None:
    # local: dask.distributed costs 'fleet status' and 'fleet report' 0.25 s of start-up (measured)
    from distributed import KilledWorker, as_completed

    futures = {}
    for cr, job in jobs:
        key = f"bridgesurvey-stage1-{job.plan_hash[:12]}-{job.measure_hash or 'plan'}-{abs(hash(job.folder)) % 10**8}"
        fut = client.submit(_task, job, key=key, pure=False, retries=TASK_RETRIES)
        futures[fut] = (cr, job)
    done = 0
    try:
        for fut in as_completed(list(futures)):
            cr, job = futures[fut]
            c = open_campaigns[cr.folder]
            try:
                result = fut.result()
                save_stage1(c, result)
                if result.centroids is not None:
                    found = sum(t.found for t in result.centroids.values())
                    cr.summary.outcomes.append(EpochOutcome(job.label, "measured",
                                                        f"{found}/{len(result.centroids)} targets found"))
                else:
                    cr.summary.outcomes.append(EpochOutcome(job.label, "planned", f"{len(result.plan.rois)} windows"))
            except SurveyError as exc:
                run.failed += 1
                cr.summary.outcomes.append(EpochOutcome(job.label, "failed", str(exc).splitlines()[0]))
            except KilledWorker:
                run.failed += 1
                cr.summary.outcomes.append(EpochOutcome(job.label, "failed", "the workers running this epoch died "
                                                    "repeatedly (out of memory?); run 'bridgesurvey process' on it"))
            lost = _workers_lost(client, fut.key)
            if lost:
                run.notes.append(f"worker lost, task retried: epoch {job.label} of {cr.name or cr.folder}"
                                 + (f" ({lost} times)" if lost > 1 else ""))
            done += 1
            report(progress, 0.95 * done / len(futures), f"{done} of {len(futures)} epochs ({cr.name} {job.label})")
    except BaseException:
        # Ctrl-C or a lost cluster: stop the rest; what was saved stays (each epoch in its own transaction)
        client.cancel(list(futures))
        raise


def _suspicious(key, dask_scheduler=None) -> int:
    """On the scheduler: how many workers died while running task ``key``."""
    ts = dask_scheduler.tasks.get(key) if dask_scheduler is not None else None
    return 0 if ts is None else int(ts.suspicious)


def _workers_lost(client, key) -> int:
    """Workers lost while running ``key`` (0 when the scheduler cannot be asked)."""
    try:
        return int(client.run_on_scheduler(_suspicious, key))
    except Exception:  # an external scheduler that refuses to run functions: nothing to say
        log.debug("cannot ask the scheduler about lost workers", exc_info=True)
        return 0

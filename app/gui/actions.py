"""What the GUI's commands do, as plain functions run in worker threads (no widgets touched here).

Each takes the session (anything with ``read()`` and ``write()``, see
:class:`app.gui.state.campaign_access.CampaignAccess`; or plain values) and a
``progress(fraction, message)`` callback, opens the campaign for just as long as it needs it, and
raises ``SurveyError`` with a message for the user.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from common.errors import InputError
from common.files import free_bytes, write_atomic
from common.processes import run_in_process
from common.progress import scaled
from lidar.io.poses import file_frames
from lidar.layout import read_layout_csv
from lidar.scanner_catalogue import CATALOGUE, get_scanner
from projects.analysis.run import analyse_campaign
from projects.demo import build_demo as build
from projects.fleet.status import fleet_status as status
from projects.onsite.check import check_epoch
from projects.onsite.check import pending_rescans as pending
from projects.onsite.stations import advise_stations
from projects.outputs.exports import export
from projects.outputs.field_sheet import write_field_sheet
from projects.outputs.inspection import change_against_baseline, inspect_target
from projects.outputs.inspection import epoch_cloud as cloud
from projects.outputs.report import write_folder_report
from projects.processing.stages import plan_epoch, save_edited_plan
from projects.processing.stages import process as run
from projects.processing.stages import set_parameter as setp
from projects.results.integrity import repair_folder, verify_campaign
from projects.results.storage import archivable_epochs
from projects.results.table import displacement_table, to_csv
from projects.series.camera import crossvalidate, import_series, save_crossval
from projects.series.environment import add_event as add
from projects.series.environment import import_env as imp
from projects.store.archive import StorageRun, archive_scans, archived_scans, folder_bytes, is_here, restore_scans
from projects.store.campaign import Campaign, parse_datetime
from projects.store.limits import set_limit_rule


def build_demo(folder: Path, progress: Callable):
    return build(folder, progress=progress)


def create_campaign(*, folder: str, name: str, layout: str, span_m: float | None, diameter_mm: float,
                    timezone: str = "UTC") -> Path:
    if not folder:
        raise InputError("choose a folder for the campaign")
    if not layout:
        raise InputError("choose the reflector layout file (id,group,x,y,z)")
    lay = read_layout_csv(layout, default_diameter_m=diameter_mm / 1000.0)
    Campaign.create(folder, name=name, layout=lay, span_m=span_m, timezone=timezone).close()
    return Path(folder)


def _validator(progress: Callable):
    """The import's file reader: each file read and checked (a scan in a project frame needs its pose)."""
    def frames_of(path, fallback):
        return file_frames(path, fallback=fallback, progress=scaled(progress, 0.0, 0.5))
    return frames_of


def add_epoch(session, v: dict, progress: Callable) -> str:
    if not v["coarse"]:
        raise InputError("choose the coarse scan of the visit")
    when = parse_datetime(v["datetime"])
    with session.write() as c:
        c.add_epoch(v["label"], when, v["coarse"], v["fines"], notes=v["notes"], frames_of=_validator(progress))
    return v["label"]


def add_fine(session, label: str, paths, progress: Callable) -> None:
    with session.write() as c:
        c.epoch(label)
        c.import_files(label, paths, "fine", frames_of=_validator(progress))


def add_setup(session, label: str, coarse, progress: Callable) -> tuple[list[int], list]:
    """Add another set-up (station) to an epoch from its coarse scan and plan it; (set-ups, their plans)."""
    with session.write() as c:
        new = c.add_setup(label, coarse, frames_of=_validator(progress))
        plans = [plan_epoch(c, label, setup=k, progress=scaled(progress, 0.5, 1.0)) for k in new]
    return new, plans


def plan(session, label: str, progress: Callable):
    with session.write() as c:
        return plan_epoch(c, label, progress=progress)


def save_plan(session, label: str, scan_plan) -> None:
    with session.write() as c:
        save_edited_plan(c, label, scan_plan)


def process(session, progress: Callable, *, accept_check: tuple[str, ...] = ()):
    """Process what is stale; ``accept_check``: epochs whose check asked for a re-scan, processed as they are."""
    with session.write() as c:
        for label in accept_check:
            c.accept_check(label)
        return run(c, progress=progress)


def pending_rescans(session) -> dict[str, str]:
    """``epoch -> the check's verdict`` of the epochs whose check asked for a re-scan not made nor accepted."""
    with session.read() as c:
        return {label: v.line() for label, v in pending(c, [e.label for e in c.epochs()]).items()}


def inspect(session, label: str, rid: str, progress: Callable):
    with session.read() as c:
        return inspect_target(c, label, rid, progress=progress)


def epoch_cloud(session, label: str, progress: Callable):
    with session.read() as c:
        return cloud(c, label, progress=progress)


def change_cloud(session, label: str, progress: Callable):
    """The M3C2 change against the baseline, computed in a process of its own: py4dgeo builds each epoch's search
    tree in one compiled call that holds Python's lock, which in the worker thread froze the window 0.8-1.0 s."""
    return run_in_process(change_against_baseline, session.folder, label, progress=progress)


def import_camera(session, v: dict, progress: Callable):
    if not v["file"]:
        raise InputError("choose the camera series file")
    progress(0.1, "reading the series")
    with session.write() as c:
        name, series = import_series(c, v["file"], name=v["name"], reflector=v["reflector"], timezone=v["timezone"],
                                     positive=v["positive"])
    return name, series.summary()


def crossval(session, progress: Callable):
    progress(0.1, "pairing LiDAR epochs with the camera")
    with session.write() as c:
        cv, _ = crossvalidate(c)
        save_crossval(c, cv)
    return cv


def export_csv(session, path: Path) -> Path:
    with session.read() as c:
        return write_atomic(path, to_csv(displacement_table(c)))


def export_xlsx(session, path: Path) -> Path:
    with session.read() as c:
        return export(c, path)


def report(session, path: Path, progress: Callable, *, detail: bool = False) -> Path:
    """The report, written in a process of its own: its drawing (matplotlib, reportlab) holds Python's lock for
    most of a second at a time, which in the worker thread froze the window (0.6-1.0 s, bench_gui_latency)."""
    return run_in_process(write_folder_report, session.folder, path, detail=detail, progress=progress)


def set_limit(session, reflector: str, rule: str) -> str:
    """Set a limit rule (also ``prediction:T``); returns what was set, in one line."""
    with session.write() as c:
        return set_limit_rule(c, reflector, rule)


def retire_reflector(session, rid: str, when: str) -> None:
    with session.write() as c:
        c.retire_reflector(rid, when)


def replace_reflector(session, old: str, new: str, when: str) -> None:
    with session.write() as c:
        c.replace_reflector(old, new, when)


def set_parameter(session, key: str, text: str) -> None:
    with session.write() as c:
        setp(c, key, text)


def field_sheet(session, label: str, path: Path, progress: Callable) -> Path:
    with session.write() as c:
        plan = plan_epoch(c, label, progress=scaled(progress, 0.0, 0.8))
        return write_field_sheet(plan, path, campaign_name=c.name, preview=c.map_preview(label),
                                 epoch_date=c.epoch(label).date)


def check(session, label: str, progress: Callable):
    with session.write() as c:
        return check_epoch(c, label, progress=progress)


def stations(session, grid_m: float, height_m: float, progress: Callable):
    """The station advice and the layout it was made on."""
    with session.read() as c:
        return advise_stations(c, grid_m=grid_m, height_m=height_m, progress=progress), c.layout()


def scanner_names() -> list[str]:
    return list(CATALOGUE)


def set_scanner(session, name: str, epoch: str | None = None) -> None:
    profile = get_scanner(name)
    with session.write() as c:
        c.set_profile(profile, epoch=epoch)


def fleet_status(folder: str) -> dict:
    return status([folder])


def analyse(session) -> dict:
    with session.read() as c:
        return analyse_campaign(c)


def import_env(session, v: dict, progress: Callable):
    """Import an environment series (``v``: file, kind, name, column, unit, timezone)."""
    if not v["file"]:
        raise InputError("choose the series file")
    progress(0.1, "reading the series")
    with session.write() as c:
        name, series = imp(c, v["file"], kind=v["kind"], name=v["name"], column=v["column"], unit=v["unit"],
                           timezone=v["timezone"])
    return name, series.summary()


def add_event(session, v: dict) -> int:
    """Record an event (``v``: date, kind, label, load_kn_m or None)."""
    with session.write() as c:
        return add(c, date=v["date"], kind=v["kind"], label=v["label"], load_kn_m=v["load_kn_m"])


def import_prediction(session, v: dict, progress: Callable) -> dict:
    """Import a design prediction (``v``: file, align_at or None for least squares, casting_date or None)."""
    # local: this function has the name of the one it calls (an import at the top would need another name)
    from projects.series.predictions import import_prediction as imp

    if not v["file"]:
        raise InputError("choose the prediction file")
    progress(0.1, "reading the prediction")
    with session.write() as c:
        before = c.settings().get("casting_date")
        if v.get("casting_date") and v["casting_date"] != before:
            setp(c, "casting_date", v["casting_date"])  # a file by concrete age needs it
        try:
            return imp(c, v["file"], align_at=v["align_at"], lsq=v["align_at"] is None)
        except BaseException:
            if c.settings().get("casting_date") != before:
                c.set_setting("casting_date", before)  # a refused import leaves the campaign as it was
            raise


@dataclass(frozen=True)
class StorageMove:
    """What an archive or restore run did or, dry, would do (Campaign ▸ Archive processed scans / Restore scans).

    ``left``: visits with scans that are not archived, and why; ``size``/``after``: the campaign folder's bytes
    before and after; ``free``: the bytes free where the scans go; ``unreachable``: the recorded archive folders
    that cannot be reached now (a restore without a folder to take the scans from).
    """
    run: StorageRun
    size: int = 0
    after: int = 0
    free: int | None = None
    left: dict[str, str] = field(default_factory=dict)
    unreachable: tuple[str, ...] = ()


def archive(session, dest: str | Path, progress: Callable, *, dry_run: bool = False) -> StorageMove:
    """Move the scans of every fully processed visit to ``dest`` (or, ``dry_run``, only say what would move)."""
    opened = session.read() if dry_run else session.write()
    with opened as c:
        labels, left = archivable_epochs(c)
        size = folder_bytes(c.folder)
        run = archive_scans(c, dest, labels, dry_run=dry_run, progress=progress)
        after = size if dry_run else folder_bytes(c.folder)
    return StorageMove(run, size, after, free_bytes(dest), left)


def restore(session, source: str | Path | None, progress: Callable, *, dry_run: bool = False) -> StorageMove:
    """Bring every archived scan back, checked, from its recorded place or from ``source`` (the folder the archive
    disk is mounted at now). Dry without ``source``: the recorded places out of reach are named, not raised."""
    opened = session.read() if dry_run else session.write()
    with opened as c:
        if dry_run and source is None:
            gone = [a for a in archived_scans(c) if not is_here(c, a.file) and not Path(a.place).is_file()]
            if gone:
                places = tuple(dict.fromkeys(str(Path(a.place).parent) for a in gone))
                return StorageMove(StorageRun(dry_run=True), unreachable=places)
        run = restore_scans(c, None, dry_run=dry_run, progress=progress, source=source)
        return StorageMove(run, free=free_bytes(c.folder))


def verify(session, progress: Callable) -> list:
    """Every problem of the open campaign, each with what to do (Campaign ▸ Verify campaign)."""
    with session.read() as c:
        return verify_campaign(c, progress=progress)


def repair(session) -> tuple[list[str], list[str]]:
    """Repair the open campaign's folder (Campaign ▸ Repair campaign): what was done, what was left."""
    return repair_folder(session.folder)

"""Scans moved out of the campaign folder once their visit is processed, and brought back when needed.

A weekly visit adds about 15 MB to a campaign, nearly all of it scans that processing read once: ten years
of visits are several gigabytes. Once a visit's stage 1 is done, its scans are needed again only to
process it again after a stage-1 parameter changed, and for the whole-scan comparison, the 3-D view and
the inspection of a target; stage 2 and the reports work from the stored centroids.

Archiving one scan (:func:`archive_scans`) goes in an order a kill -9 cannot break:

1. it is copied to ``DEST/<its stored name>`` under a temporary name (``.archive-<hex>``), flushed to disk,
   read back (from the disk: its pages are dropped from memory first) and checked against the SHA-256
   recorded at its import, renamed, made read-only;
2. the move is appended to the journal of imports (kind ``archive``), so a database restored from an older
   backup still knows where the scan went (``bridgesurvey repair``);
3. the copy's place is recorded in ``archived_files`` (one transaction, logged);
4. the scan's links under ``scans/by-visit/`` and the scan itself are removed from the campaign folder.

Killed before step 3 the scan is where it was (the copy in DEST is reused, after its check, by the next
run); killed after it, the scan is in both places until the next run finishes the move. A scan counts as
here while its file is in ``scans/``: only a scan that is archived *and* gone from the folder stops a
command (:func:`check_present`, one line naming the scans, where they are and ``archive --restore``).
Restoring (:func:`restore_scans`) is the same in the other direction: copied in under the import's
temporary name, checked, renamed, journaled, the record removed, the visit's links made again, then the
archived copy removed. The ``files`` rows never change: ``verify`` checks an archived scan at its place
when that is reachable, and names it as archived, not checked, when it is not.
"""
from __future__ import annotations

import contextlib
import os
import re
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from common.files import MB, disk_full_error, ensure_free, is_disk_full, sha256_of
from common.progress import ProgressCallback, report, scaled
from projects.store import journal
from projects.store.campaign import Campaign
from projects.store.errors import CampaignError, ScansArchivedError
from projects.store.imports import BY_VISIT, SCANS_DIR, link_by_visit, not_writable, visit_link_name
from projects.store.records import ScanFile, now_iso

#: The temporary name of a copy being written into an archive folder.
TEMP_ARCHIVE = re.compile(r"^\.archive-[0-9a-f]{32}$")
#: Room kept free beyond the copies themselves.
ARCHIVE_MARGIN_BYTES = MB


@dataclass(frozen=True)
class ArchivedScan:
    """A scan recorded as archived: its ``files`` row, the absolute path of its copy, and when it was recorded."""

    file: ScanFile
    place: str
    archived: str

    @property
    def name(self) -> str:
        """The scan's stored file name (``<sha16>_<original name>``)."""
        return Path(self.file.stored_path).name


@dataclass
class StorageRun:
    """What an archive or restore run did (or, dry, would do): each scan's stored path, epoch, size and place."""

    moved: list[tuple[str, str, int, str]] = field(default_factory=list)
    dry_run: bool = False

    @property
    def bytes(self) -> int:
        return sum(m[2] for m in self.moved)

    @property
    def epochs(self) -> list[str]:
        return list(dict.fromkeys(m[1] for m in self.moved))


# ---------------------------------------------------------------------------------------------- reading
def archived_scans(c: Campaign, epochs: Iterable[str] | None = None) -> list[ArchivedScan]:
    """The scans recorded as archived (of ``epochs``, default all), by epoch date then stored path."""
    rows = c.conn.execute("SELECT f.*, a.place AS place, a.archived AS archived_at FROM archived_files a "
                          "JOIN files f ON f.sha256 = a.sha256 JOIN epochs e ON e.label = f.epoch "
                          "ORDER BY e.datetime, e.label, f.stored_path").fetchall()
    wanted = None if epochs is None else set(epochs)
    out = []
    for r in rows:
        d = dict(r)
        place, at = d.pop("place"), d.pop("archived_at")
        if wanted is None or d["epoch"] in wanted:
            out.append(ArchivedScan(ScanFile(**d), place, at))
    return out


def is_here(c: Campaign, f: ScanFile) -> bool:
    """Whether a scan's file is in the campaign folder (archived or not)."""
    return (c.folder / f.stored_path).is_file()


def away(c: Campaign, files: Sequence[ScanFile]) -> list[ArchivedScan]:
    """Those of ``files`` that are archived and no longer in the campaign folder.

    The database is asked only when a file is missing (a stage-1 job reads the store once, in one snapshot).
    """
    missing = [f for f in files if not is_here(c, f)]
    if not missing:
        return []
    recorded = {a.file.sha256: a for a in archived_scans(c, {f.epoch for f in missing})}
    return [recorded[f.sha256] for f in missing if f.sha256 in recorded]


def archived_line(folder: Path, gone: Sequence[ArchivedScan], what: str) -> str:
    """The one line for a command that needs archived scans: which, where they are, and how to bring them back."""
    epochs = list(dict.fromkeys(a.file.epoch for a in gone))
    places = list(dict.fromkeys(str(Path(a.place).parent) for a in gone))
    names = ", ".join(a.name for a in gone)
    option = f" --epoch {epochs[0]}" if len(epochs) == 1 else ""
    return (f"epoch {', '.join(epochs)}: {what} needs the scan(s) {names}, which were archived to "
            f"{' and '.join(places)}; bring them back with 'bridgesurvey archive {folder} --restore{option}' and run "
            "the command again (the results stored so far are kept)")


def check_present(c: Campaign, files: Sequence[ScanFile], what: str) -> None:
    """Raise :class:`ScansArchivedError` (one line, :func:`archived_line`) when any of ``files`` is archived away."""
    gone = away(c, files)
    if gone:
        raise ScansArchivedError(archived_line(c.folder, gone, what))


def copy_state(a: ArchivedScan) -> str:
    """``"checked"`` (the copy is there with the scan's checksum), ``"changed"`` or ``"unreachable"``."""
    p = Path(a.place)
    try:
        if not p.is_file():
            return "unreachable"
        return "checked" if sha256_of(p) == a.file.sha256 else "changed"
    except OSError:
        return "unreachable"


def folder_bytes(folder: Path) -> int:
    """The bytes of every file under ``folder`` (links not followed: a by-visit link costs nothing)."""
    total = 0
    for root, _dirs, names in os.walk(folder):
        for n in names:
            with contextlib.suppress(OSError):
                st = os.lstat(os.path.join(root, n))
                if not os.path.islink(os.path.join(root, n)):
                    total += st.st_size
    return total


def storage_summary(c: Campaign) -> dict:
    """The campaign's size on disk and its scans: ``{"size_bytes", "scans_here", "scans_archived": {folder: n}}``.

    A scan recorded as archived whose file is still in the folder (an archive run stopped before it removed
    it) counts as here and as archived.
    """
    total = c.conn.execute("SELECT count(*) FROM files").fetchone()[0]
    places: dict[str, int] = {}
    here_too = 0
    for a in archived_scans(c):
        folder = str(Path(a.place).parent)
        places[folder] = places.get(folder, 0) + 1
        here_too += is_here(c, a.file)
    n_archived = sum(places.values())
    return {"size_bytes": folder_bytes(c.folder), "scans_here": total - n_archived + here_too,
            "scans_archived": places}


# ---------------------------------------------------------------------------------------------- moving
def check_destination(c: Campaign, dest: str | os.PathLike) -> Path:
    """The archive folder, resolved: an existing folder outside the campaign that this user may write, or one line."""
    dest = Path(dest)
    tail = "; nothing was changed"
    if not dest.exists():
        raise CampaignError(f"{dest}: no such folder (is the archive disk connected and mounted?); create it or "
                            f"give another with --to{tail}")
    if not dest.is_dir():
        raise CampaignError(f"{dest}: is a file, not a folder; give the folder to archive the scans into{tail}")
    real, camp = dest.resolve(), c.folder.resolve()
    if real == camp or camp in real.parents:
        raise CampaignError(f"{dest}: is inside the campaign folder {c.folder}, so archiving there frees nothing; give "
                            f"a folder elsewhere (another disk){tail}")
    probe = real / f".archive-{uuid.uuid4().hex}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        os.close(fd)
        probe.unlink()
    except OSError as exc:
        if is_disk_full(exc):
            raise disk_full_error(real, MB) from None
        raise CampaignError(f"{dest}: cannot write into this folder ({exc.strerror or exc}); make it writable or "
                            f"give another with --to{tail}") from None
    return real


def _fsync_dir(d: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(d, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _copy_checked(src: Path, target: Path, sha256: str, temp_prefix: str, *, what: str) -> None:
    """Copy ``src`` to ``target`` (temporary name, fsync, read back against ``sha256``, rename, read-only).

    A file already at ``target`` with the checksum is kept (a run killed after its copy). A full disk is a
    :class:`~common.files.DiskFullError`; a copy that does not match is a :class:`CampaignError`; either way no
    temporary file is left.
    """
    size = src.stat().st_size
    if target.is_file() and target.stat().st_size == size and sha256_of(target) == sha256:
        return
    tmp = target.parent / f"{temp_prefix}{uuid.uuid4().hex}"
    try:
        with open(src, "rb") as fin, open(tmp, "wb") as fout:
            while block := fin.read(8 << 20):
                fout.write(block)
            fout.flush()
            os.fsync(fout.fileno())
            if hasattr(os, "posix_fadvise"):  # the check below reads the copy from the disk, not from memory
                os.posix_fadvise(fout.fileno(), 0, 0, os.POSIX_FADV_DONTNEED)
        if sha256_of(tmp) != sha256:
            why = ("the scan changed since its import: 'bridgesurvey verify' says what to do"
                   if sha256_of(src) != sha256 else f"the copy was damaged on its way: check the disk of {target.parent}")
            raise CampaignError(f"{src}: its copy does not match the checksum recorded at its import ({why}); "
                                f"{what}")
        os.replace(tmp, target)
        target.chmod(0o444)
        _fsync_dir(target.parent)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, OSError) and is_disk_full(exc):
            raise disk_full_error(target.parent, size + ARCHIVE_MARGIN_BYTES) from None
        if isinstance(exc, PermissionError):
            raise not_writable(target.parent) from None
        raise


def _unlink_visit_links(c: Campaign, f: ScanFile) -> None:
    """Remove the links to a scan under ``scans/by-visit/<epoch>/`` (and the visit's folder when it is left empty)."""
    d = c.folder / SCANS_DIR / BY_VISIT / f.epoch
    if not d.is_dir():
        return
    target = (c.folder / f.stored_path).resolve()
    for p in list(d.iterdir()):
        if p.is_symlink() and (d / os.readlink(p)).resolve() == target:
            with contextlib.suppress(OSError):
                p.unlink()
    with contextlib.suppress(OSError):
        d.rmdir()  # only when empty


def _clean_temp(folder: Path) -> None:
    """Remove the temporary copies a killed archive run left in an archive folder (only names of this module)."""
    with contextlib.suppress(OSError):
        for p in folder.iterdir():
            if TEMP_ARCHIVE.match(p.name) and p.is_file():
                with contextlib.suppress(OSError):
                    p.unlink()


def archive_scans(c: Campaign, dest: str | os.PathLike, epochs: Sequence[str], *, dry_run: bool = False,
                  progress: ProgressCallback | None = None) -> StorageRun:
    """Move the scans of ``epochs`` still in the campaign folder to ``dest`` (see the module notes).

    The caller chooses the epochs (fully processed ones: :func:`projects.results.storage.archivable_epochs`). A
    missing, unwritable or full ``dest``, or one inside the campaign, is one line before anything is moved.
    """
    real = check_destination(c, dest)
    recorded = {a.file.sha256: a for a in archived_scans(c, epochs)}
    todo = [f for lab in epochs for f in c.files(lab, setup=None) if is_here(c, f)]
    run = StorageRun(dry_run=dry_run)
    new = [f for f in todo if not (real / Path(f.stored_path).name).is_file()]  # a copy there is reused
    if dry_run:
        run.moved = [(f.stored_path, f.epoch, f.size, str(real / Path(f.stored_path).name)) for f in todo]
        return run
    ensure_free(real, sum(f.size for f in new) + ARCHIVE_MARGIN_BYTES)
    _clean_temp(real)
    for k, f in enumerate(todo):
        report(progress, k / max(len(todo), 1), f"archiving {f.stored_path}")
        run.moved.append(_archive_one(c, real, f, recorded.get(f.sha256)))
    report(progress, 1.0, "archived")
    return run


def _archive_one(c: Campaign, real: Path, f: ScanFile, recorded: ArchivedScan | None) -> tuple[str, str, int, str]:
    src = c.folder / f.stored_path
    if recorded is not None and copy_state(recorded) == "checked":
        place = Path(recorded.place)  # recorded by a run stopped before it removed the scan: finish the move
    else:
        place = real / src.name
        _copy_checked(src, place, f.sha256, ".archive-", what="it was not archived (it stays in the campaign)")
        mark = c.append_journal({"kind": "archive", "stored_path": "", "scan": f.stored_path, "sha256": f.sha256,
                            "epoch": f.epoch, "size": f.size, "place": str(place), "time": now_iso()})
        try:
            with c.transaction() as conn:
                conn.execute("INSERT OR REPLACE INTO archived_files(sha256, place, archived) VALUES (?, ?, ?)",
                             (f.sha256, str(place), now_iso()))
                c.log_action(conn, "archive", f.epoch, {"scan": f.stored_path, "place": str(place)})
        except BaseException:
            journal.truncate(c.folder, mark)
            raise
    _unlink_visit_links(c, f)
    try:
        src.unlink()
    except FileNotFoundError:
        pass
    except PermissionError:
        raise not_writable(src.parent) from None
    return (f.stored_path, f.epoch, f.size, str(place))


def restore_scans(c: Campaign, epochs: Sequence[str] | None = None, *, dry_run: bool = False,
                  progress: ProgressCallback | None = None, source: str | os.PathLike | None = None) -> StorageRun:
    """Bring the archived scans of ``epochs`` (default all) back into the campaign folder, checked (module notes).

    Every copy must be reachable and the campaign's disk must hold them all, else one line before anything moves.
    ``source``: the folder the archive disk is mounted at now, when the recorded place cannot be reached (another
    computer, another mount point): the copies not at their recorded place are taken from there, each checked
    against the checksum of its import and its new place recorded (:func:`relocate_archived`) before it is copied.
    The archived copy is removed once the scan is back and recorded so (a copy that cannot be removed is kept;
    one that a stopped restore left is removed by the next).
    """
    scans = archived_scans(c, epochs)
    if source is not None:
        scans = relocate_archived(c, scans, source, dry_run=dry_run, progress=scaled(progress, 0.0, 0.5))
        progress = scaled(progress, 0.5, 1.0)
    run = StorageRun(dry_run=dry_run)
    unreachable = [a for a in scans if not is_here(c, a.file) and not Path(a.place).is_file()]
    if unreachable:
        places = list(dict.fromkeys(str(Path(a.place).parent) for a in unreachable))
        also = "" if source is None else f" nor in {source}"
        raise CampaignError(f"{' and '.join(places)}: the archived copies of {len(unreachable)} scan(s) are not there"
                            f"{also} (first {unreachable[0].name} of epoch {unreachable[0].file.epoch}); connect the "
                            "archive disk and run the command again, or name the folder it is mounted at now "
                            "(--from FOLDER); nothing was changed")
    run.moved = [(a.file.stored_path, a.file.epoch, a.file.size, a.place) for a in scans]
    if dry_run:
        return run
    _remove_restored_copies(c)
    scans_dir = c.folder / SCANS_DIR
    ensure_free(scans_dir, sum(a.file.size for a in scans if not is_here(c, a.file)) + ARCHIVE_MARGIN_BYTES)
    for k, a in enumerate(scans):
        report(progress, k / max(len(scans), 1), f"restoring {a.file.stored_path}")
        _restore_one(c, a)
    report(progress, 1.0, "restored")
    return run


def relocate_archived(c: Campaign, scans: Sequence[ArchivedScan], source: str | os.PathLike, *,
                      dry_run: bool = False, progress: ProgressCallback | None = None) -> list[ArchivedScan]:
    """``scans``, those not at their recorded place found in ``source`` (an archive disk mounted elsewhere) instead.

    Each copy found there under its stored name is checked against the checksum recorded at its import, then its
    new place is recorded (journal, ``archived_files``, the log) unless ``dry_run``.

    A copy in ``source`` with another checksum, or a ``source`` that is no folder, is one line before anything is
    recorded. Scans found neither place keep their recorded place (the caller says they cannot be reached).
    """
    src = Path(source)
    if not src.is_dir():
        raise CampaignError(f"{source}: no such folder (is the archive disk connected and mounted?); give the folder "
                            "the archived scans are in; nothing was changed")
    found: dict[str, Path] = {}
    away_now = [a for a in scans if not is_here(c, a.file) and not Path(a.place).is_file()]
    for k, a in enumerate(away_now):
        cand = src / a.name
        if not cand.is_file():
            continue
        report(progress, k / max(len(away_now), 1), f"checking {cand.name}")
        try:
            same = sha256_of(cand) == a.file.sha256
        except OSError as exc:
            raise CampaignError(f"{cand}: cannot be read ({exc.strerror or exc}); nothing was changed") from None
        if not same:
            raise CampaignError(f"{cand}: does not match the checksum recorded at its import (epoch {a.file.epoch}): "
                                "it is not the archived scan, or it was damaged; it stays where it is; nothing was "
                                "changed")
        found[a.file.sha256] = cand.resolve()
    report(progress, 1.0, f"{len(found)} archived scan(s) found in {source}")
    if dry_run or not found:
        return [ArchivedScan(a.file, str(found.get(a.file.sha256, a.place)), a.archived) for a in scans]
    out = []
    for a in scans:
        place = found.get(a.file.sha256)
        if place is None:
            out.append(a)
            continue
        mark = c.append_journal({"kind": "archive", "stored_path": "", "scan": a.file.stored_path,
                                 "sha256": a.file.sha256, "epoch": a.file.epoch, "size": a.file.size,
                                 "place": str(place), "time": now_iso()})
        try:
            with c.transaction() as conn:
                conn.execute("UPDATE archived_files SET place = ? WHERE sha256 = ?", (str(place), a.file.sha256))
                c.log_action(conn, "relocate", a.file.epoch, {"scan": a.file.stored_path, "from": a.place,
                                                              "place": str(place)})
        except BaseException:
            journal.truncate(c.folder, mark)
            raise
        out.append(ArchivedScan(a.file, str(place), a.archived))
    return out


def _restore_one(c: Campaign, a: ArchivedScan) -> None:
    f = a.file
    dst = c.folder / f.stored_path
    if not (dst.is_file() and sha256_of(dst) == f.sha256):
        if dst.exists():  # a damaged file under the scan's name: the checked copy takes its place
            dst.chmod(0o644)
        _copy_checked(Path(a.place), dst, f.sha256, ".import-", what="it stays archived")
    mark = c.append_journal({"kind": "restore", "stored_path": "", "scan": f.stored_path, "sha256": f.sha256,
                        "epoch": f.epoch, "place": a.place, "time": now_iso()})
    try:
        with c.transaction() as conn:
            conn.execute("DELETE FROM archived_files WHERE sha256 = ?", (f.sha256,))
            c.log_action(conn, "restore", f.epoch, {"scan": f.stored_path, "place": a.place})
    except BaseException:
        journal.truncate(c.folder, mark)
        raise
    link_by_visit(c.folder, f.stored_path, f.epoch, visit_link_name(f.role, f.setup, Path(f.original_path).name))
    with contextlib.suppress(OSError):
        Path(a.place).unlink()


# ---------------------------------------------------------------------------------------------- repair
def _last_moves(c: Campaign) -> dict[str, dict]:
    """The journal's last archive or restore entry of each scan, by checksum."""
    last: dict[str, dict] = {}
    for e in journal.entries(c.folder):
        if e.get("kind") in ("archive", "restore") and isinstance(e.get("sha256"), str) and e.get("place"):
            last[e["sha256"]] = e
    return last


def archived_from_journal(c: Campaign) -> list[tuple[str, str, str]]:
    """(sha256, place, time) of each scan the journal last saw archived (a later restore undoes it), in order."""
    return [(sha, str(e["place"]), str(e.get("time", ""))) for sha, e in _last_moves(c).items()
            if e["kind"] == "archive"]


def _remove_restored_copies(c: Campaign) -> None:
    """Remove the archived copies of scans restored by a run stopped before it removed them.

    Only a copy the journal last saw restored, whose scan is back in the folder and no longer recorded as
    archived, with the scan's checksum: never a copy the campaign still counts on.
    """
    recorded = {a.file.sha256 for a in archived_scans(c)}
    for sha, e in _last_moves(c).items():
        place = Path(e["place"])
        if e["kind"] != "restore" or sha in recorded or not place.is_file():
            continue
        here = c.folder / str(e.get("scan", ""))
        with contextlib.suppress(OSError):
            if here.is_file() and sha256_of(here) == sha and sha256_of(place) == sha:
                place.unlink()


def repair_archived(c: Campaign) -> list[str]:
    """Record again as archived the scans the journal has archived, that the database lists and that are gone.

    For a database restored from a backup older than an archive run (or one that lost ``archived_files``): the
    scans are not lost, they are where the journal says. Returns what was done, a line each.
    """
    out = []
    for sha, place, when in archived_from_journal(c):
        row = c.conn.execute("SELECT * FROM files WHERE sha256 = ?", (sha,)).fetchone()
        if row is None:
            continue
        f = ScanFile(**dict(row))
        if is_here(c, f) or c.conn.execute("SELECT 1 FROM archived_files WHERE sha256 = ?", (sha,)).fetchone():
            continue
        with c.transaction() as conn:
            conn.execute("INSERT INTO archived_files(sha256, place, archived) VALUES (?, ?, ?)", (sha, place, when))
            c.log_action(conn, "repair", f.epoch, {"archived": f.stored_path, "place": place})
        reach = "" if Path(place).is_file() else " (not reachable now)"
        out.append(f"{f.stored_path}: recorded again as archived to {place}{reach}, as the journal of imports has it")
    return out


"""Files copied into a campaign: checked, read-only, journaled, and never deleted once imported.

A file is copied under a temporary name (``.import-<hex>``), flushed to disk, renamed to its final
name (``<first 16 hex digits of its sha256>_<original name>``) and made read-only; the import's
journal line (:mod:`projects.store.journal`) is written, then the database transaction commits. A
process killed at any moment leaves at most a temporary file (removed by the next writer: the only
files the product ever deletes from an import folder) or a complete file the database may not list
(reported by ``status`` and ``verify``, registered again by ``repair``; never removed). Each stored scan is
also linked under the name the surveyor gave it, per visit (``scans/by-visit/<epoch>/``, :func:`link_by_visit`).
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import re
import uuid
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from common.errors import SurveyError
from common.files import MB, disk_full_error, ensure_free, is_disk_full, sha256_of
from lidar.io import sniff_format
from lidar.io.e57_header import check_e57
from lidar.io.las_header import check_las_header
from projects.store.errors import CampaignError

log = logging.getLogger(__name__)

SCANS_DIR = "scans"
CAMERA_DIR = "camera"
ENV_DIR = "environment"
PREDICTION_DIR = "prediction"
#: Each import folder and the table that lists its files.
IMPORT_DIRS = {SCANS_DIR: "files", CAMERA_DIR: "camera_series", ENV_DIR: "env_series", PREDICTION_DIR: "predictions"}
#: The temporary name of a file being copied in.
TEMP_IMPORT = re.compile(r"^\.import-[0-9a-f]{32}$")
#: Room kept free beyond the file itself (journal line, database rows, write-ahead log).
IMPORT_MARGIN_BYTES = MB


@dataclass(frozen=True)
class Copied:
    """A file copied in: its checksum, path relative to the campaign, size, and whether this copy created it."""

    sha256: str
    rel: str
    size: int
    created: bool


def stored_name(sha256: str, original_name: str) -> str:
    """The name a file is stored under in its import folder.

    Examples
    --------
    >>> stored_name("0123456789abcdef" + "0" * 48, "visit 8/coarse scan.laz")
    '0123456789abcdef_visit_8_coarse_scan.laz'
    """
    safe = "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in original_name)
    return f"{sha256[:16]}_{safe}"


#: Under the scans folder: one folder per visit with a link, named as the surveyor's file was, to each stored scan
#: (``scans/by-visit/<epoch>/<role>-<original name>``). The stored files keep their checksum names (what the
#: campaign's database and ``verify`` go by); the links are for a person looking for a visit's scans.
BY_VISIT = "by-visit"


def visit_link_name(role: str, setup: int, original_name: str) -> str:
    """The name of a stored scan's link in its visit's folder.

    >>> visit_link_name("fine", 1, "M3 rescan.laz"), visit_link_name("coarse", 2, "c.e57")
    ('fine-M3 rescan.laz', 'coarse-setup2-c.e57')
    """
    name = original_name.replace("/", "_").replace("\\", "_").lstrip(".") or "scan"
    return f"{role}{'' if setup == 1 else f'-setup{setup}'}-{name}"


def link_by_visit(folder: Path, rel: str, epoch: str, name: str) -> Path | None:
    """Link the stored scan ``folder/rel`` as ``scans/by-visit/<epoch>/<name>`` (a relative symbolic link).

    A name already taken by another file gets ``-2``, ``-3``…; an existing link to the same file is kept, and so
    is a plain file of the same size (the campaign copied by a tool that follows links). Where the
    file system has no symbolic links the log says so and None is returned: the link is a convenience, the
    import stands without it.
    """
    d = folder / SCANS_DIR / BY_VISIT / epoch
    try:
        d.mkdir(parents=True, exist_ok=True)
        target = Path(os.path.relpath(folder / rel, d))
        stem, dot, ext = name.rpartition(".") if "." in name else (name, "", "")
        for k in range(1, 1000):
            link = d / (name if k == 1 else f"{stem}-{k}{dot}{ext}")
            if link.is_symlink():
                if Path(os.readlink(link)) == target:
                    return link
                continue
            if link.is_file() and link.stat().st_size == (folder / rel).stat().st_size:
                return link  # the campaign was copied by a tool that follows links: the copy stands for the link
            if not link.exists():
                link.symlink_to(target)
                return link
    except OSError as exc:
        log.warning("no link to %s in %s: %s", rel, d, exc)
    return None


def copy_in(folder: Path, src: Path, sub: str, *, sha256: str | None = None) -> Copied:
    """Copy ``src`` into ``folder/sub`` (temporary name, fsync, rename, read-only).

    ``sha256`` is the file's checksum when the caller has it (the import checked the file against the
    campaign with it): the copy then does not hash the file again. Without it the copy hashes as it copies.

    A file already there under its final name is kept as it is (an import run again after a crash,
    or a file the database lost): ``created`` is False. A file already inside ``folder/sub`` is taken
    where it is. A full disk is a :class:`~common.files.DiskFullError`, checked before copying
    and met while copying, with nothing left behind.
    """
    target = folder / sub
    try:
        target.mkdir(exist_ok=True)
    except PermissionError:
        raise not_writable(target) from None
    size = src.stat().st_size
    if src.resolve().parent == target.resolve():
        sha = sha256 or sha256_of(src)
        return Copied(sha, f"{sub}/{src.name}", size, False)
    ensure_free(target, size + IMPORT_MARGIN_BYTES)
    tmp = target / f".import-{uuid.uuid4().hex}"
    h = hashlib.sha256() if sha256 is None else None
    try:
        with open(src, "rb") as fin, open(tmp, "wb") as fout:
            while block := fin.read(8 << 20):
                if h is not None:
                    h.update(block)
                fout.write(block)
            fout.flush()
            os.fsync(fout.fileno())
        sha = h.hexdigest() if h is not None else str(sha256)
        rel = f"{sub}/{stored_name(sha, src.name)}"
        final = folder / rel
        if final.exists():
            tmp.unlink()
            return Copied(sha, rel, size, False)
        os.replace(tmp, final)
        final.chmod(0o444)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(exc, Exception) and is_disk_full(exc):
            raise disk_full_error(target, size + IMPORT_MARGIN_BYTES) from None
        if isinstance(exc, PermissionError) and exc.filename and Path(exc.filename).parent == target:
            raise not_writable(target) from None
        raise
    return Copied(sha, rel, size, True)


def not_writable(path: Path) -> CampaignError:
    """The one line for a campaign folder (or its database) this user may not write: nothing was changed."""
    what = "folder" if path.is_dir() else "file"
    return CampaignError(f"{path}: this {what} is read-only (permission denied), so the command cannot write the "
                         f"campaign; nothing was changed: make it writable (e.g. chmod -R u+w '{path}') and run the "
                         "command again")


def remove_uncommitted(folder: Path, copied: Iterable[Copied]) -> None:
    """Remove the files an import created when its transaction did not commit (never one that was there)."""
    for c in copied:
        if c.created:
            p = folder / c.rel
            with contextlib.suppress(OSError):
                p.chmod(0o644)
                p.unlink()


def clean_temp_files(folder: Path, db_name: str) -> list[str]:
    """Remove the temporary files an interrupted import or creation left; returns what was removed.

    Only files named as this module (``.import-<hex>``) or ``Campaign.create``
    (``.<db_name>.<hex>.part``) name their temporary files are touched.
    """
    removed = []
    for sub in IMPORT_DIRS:
        d = folder / sub
        for p in d.iterdir() if d.is_dir() else ():
            if TEMP_IMPORT.match(p.name) and p.is_file():
                with contextlib.suppress(OSError):
                    p.unlink()
                    removed.append(f"{sub}/{p.name}")
    for p in folder.glob(f".{db_name}.*.part"):
        if re.fullmatch(rf"\.{re.escape(db_name)}\.[0-9a-f]{{32}}\.part", p.name):
            with contextlib.suppress(OSError):
                p.unlink()
                removed.append(p.name)
    return removed


def folder_files(folder: Path) -> list[str]:
    """Every imported-looking file of the import folders (temporary and hidden files aside), relative paths."""
    out = []
    for sub in IMPORT_DIRS:
        d = folder / sub
        for p in sorted(d.iterdir()) if d.is_dir() else ():
            if p.is_file() and not p.name.startswith("."):
                out.append(f"{sub}/{p.name}")
    return out


def header_facts(path: Path) -> dict:
    """What a scan file's header says, to recognise it again: format, and for LAS/E57 versions and counts.

    Raises the reader's :class:`~common.errors.ScanFormatError` when the header is not readable.
    """
    kind = sniff_format(path)
    facts: dict = {"format": kind}
    if kind == "las":
        h = check_las_header(path)
        facts.update(version=h.version, point_format=h.point_format, point_count=h.point_count)
    elif kind == "e57":
        e = check_e57(path)
        facts.update(version=e.version, records=[s.record_count for s in e.scans])
    with open(path, "rb") as fh:
        facts["head_sha256"] = hashlib.sha256(fh.read(64 << 10)).hexdigest()
    return facts


def header_matches(path: Path, recorded: dict | None) -> bool:
    """Whether the header of ``path`` reads and says what was recorded at its import."""
    try:
        facts = header_facts(path)
    except (SurveyError, OSError):
        return False
    return recorded is None or all(facts.get(k) == v for k, v in recorded.items())

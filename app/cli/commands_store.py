"""Store commands: verify a campaign end to end, repair what a restore or damage left, archive processed scans."""
from __future__ import annotations

import datetime as dt
from pathlib import Path

from app.cli.output import dump_json
from app.cli.progress import progress_bar
from common import files
from common.errors import InputError
from projects.results.integrity import repair_folder, verify_campaign
from projects.results.storage import archivable_epochs
from projects.store.archive import StorageRun, archive_scans, folder_bytes, restore_scans
from projects.store.campaign import Campaign, parse_datetime

#: Exit status of 'verify' when it found something to do.
EXIT_FOUND = 3


def cmd_verify(args) -> int:
    with Campaign.open(args.dir, writable=False) as c:
        with progress_bar("verifying") as cb:
            findings = verify_campaign(c, progress=cb)
        n_files = len(c.listed_files())
    problems = [f for f in findings if not f.is_note]
    notes = len(findings) - len(problems)
    if args.json:
        dump_json({"ok": not problems, "files_checked": n_files - notes,
                   "findings": [{"kind": f.kind, "subject": f.subject, "problem": f.problem, "action": f.action}
                                for f in findings]})
    else:
        for f in findings:
            print(f"{f.kind.upper()} {f.line()}")
        print(f"checked the database, {n_files - notes} imported file(s) and every stored result: "
              + ("no problem found" if not problems else f"{len(problems)} thing(s) to do")
              + (f"; {notes} archived scan(s) not reachable, not checked" if notes else ""))
    return EXIT_FOUND if problems else 0


def cmd_repair(args) -> int:
    done, left = repair_folder(args.dir)
    if args.json:
        dump_json({"done": done, "left": left})
    else:
        for line in done:
            print(f"repaired: {line}")
        for line in left:
            print(f"left: {line}")
        print(f"{len(done)} repair(s), {len(left)} left as they are; nothing was deleted"
              + ("; run 'bridgesurvey process' to bring the results up to date" if done else ""))
    return EXIT_FOUND if left else 0


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB"


def _per_visit(run: StorageRun, verb: str, where: str) -> list[str]:
    """One line per visit: how many scans, their size, and the archive folder(s) (``where``: "to" or "from")."""
    lines = []
    for label in run.epochs:
        mine = [m for m in run.moved if m[1] == label]
        places = sorted({str(Path(m[3]).parent) for m in mine})
        lines.append(f"{label}: {verb} {len(mine)} scan(s), {_mb(sum(m[2] for m in mine))}, {where} "
                     f"{', '.join(places)}")
    return lines


def cmd_archive(args) -> int:
    if args.restore:
        if args.to is not None or args.before:
            raise InputError("--restore brings the scans back from where the campaign recorded them: it takes no --to "
                             "nor --before (--epoch LABEL for one visit)")
        with Campaign.open(args.dir, writable=not args.dry_run) as c:
            labels = None
            if args.epoch:
                c.epoch(args.epoch)
                labels = [args.epoch]
            with progress_bar("restoring", enabled=not args.dry_run) as cb:
                run = restore_scans(c, labels, dry_run=args.dry_run, progress=cb, source=args.source)
        return _said(args, run, "restore", {})
    if args.source is not None:
        raise InputError("--from goes with --restore: it names where the archive disk is mounted now; to archive, "
                         "give the folder to move the scans into with --to DEST")
    if args.to is None:
        raise InputError("say where to move the scans: --to DEST (a folder on another disk), or --restore to bring "
                         "archived scans back")
    if args.epoch:
        raise InputError("--epoch goes with --restore; to archive, every fully processed visit is moved (--before "
                         "DATE for the older ones only)")
    before = dt.datetime.fromisoformat(parse_datetime(args.before)) if args.before else None
    with Campaign.open(args.dir, writable=not args.dry_run) as c:
        labels, left = archivable_epochs(c, before)
        size = folder_bytes(c.folder)
        with progress_bar("archiving", enabled=not args.dry_run) as cb:
            run = archive_scans(c, args.to, labels, dry_run=args.dry_run, progress=cb)
        after = size if args.dry_run else folder_bytes(c.folder)
    return _said(args, run, "archive", left, size=size, after=after)


def _said(args, run: StorageRun, action: str, left: dict[str, str], *, size: int = 0, after: int = 0) -> int:
    """Print what an archive or restore run did (or would do); exit status 0."""
    if args.json:
        dump_json({"action": action, "dry_run": run.dry_run, "bytes": run.bytes,
                   "scans": [{"scan": m[0], "epoch": m[1], "size": m[2], "place": m[3]} for m in run.moved],
                   "not_archived": [{"epoch": k, "why": v} for k, v in left.items()],
                   **({"size_before_bytes": size, "size_after_bytes": after} if action == "archive" else {})})
        return 0
    verb = {("archive", False): "moved", ("archive", True): "would move", ("restore", False): "brought back",
            ("restore", True): "would bring back"}[(action, run.dry_run)]
    for line in _per_visit(run, verb, "to" if action == "archive" else "from"):
        print(line)
    for label, why in left.items():
        print(f"{label}: not archived: {why}")
    n, visits = len(run.moved), len(run.epochs)
    if action == "archive":
        if run.dry_run:
            free = files.free_bytes(args.to)
            room = "" if free is None else (f"; {args.to} has {_mb(free)} free" + (
                "" if free >= run.bytes else f": not enough, free {_mb(run.bytes - free)} more first"))
            print(f"dry run: would move {n} scan(s) of {visits} visit(s), freeing {_mb(run.bytes)} of the campaign's "
                  f"{_mb(size)}{room}; nothing was changed")
        else:
            print(f"archived {n} scan(s) of {visits} visit(s): {_mb(size - after)} freed, the campaign folder now "
                  f"holds {_mb(after)}" + ("" if n else " (nothing to archive)"))
    else:
        print(f"dry run: would bring back {n} scan(s) of {visits} visit(s) ({_mb(run.bytes)}); nothing was changed"
              if run.dry_run else f"brought back {n} scan(s) of {visits} visit(s) ({_mb(run.bytes)}), each checked "
              "against its checksum" + ("" if n else " (nothing was archived)"))
    return 0

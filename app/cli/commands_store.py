"""Store commands: verify a campaign end to end, and repair what a restore or damage left."""
from __future__ import annotations

from app.cli.output import dump_json
from app.cli.progress import progress_bar
from projects.results.integrity import repair_folder, verify_campaign
from projects.store.campaign import Campaign

#: Exit status of 'verify' when it found something to do.
EXIT_FOUND = 3


def cmd_verify(args) -> int:
    with Campaign.open(args.dir, writable=False) as c:
        with progress_bar("verifying") as cb:
            findings = verify_campaign(c, progress=cb)
        n_files = len(c.listed_files())
    if args.json:
        dump_json({"ok": not findings, "files_checked": n_files,
                   "findings": [{"kind": f.kind, "subject": f.subject, "problem": f.problem, "action": f.action}
                                for f in findings]})
    else:
        for f in findings:
            print(f"{f.kind.upper()} {f.line()}")
        print(f"checked the database, {n_files} imported file(s) and every stored result: "
              + ("no problem found" if not findings else f"{len(findings)} thing(s) to do"))
    return EXIT_FOUND if findings else 0


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

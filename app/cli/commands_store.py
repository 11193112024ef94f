"""Store commands: verify a campaign end to end, and repair what a restore or damage left."""
from __future__ import annotations

from app.cli.args import add_dir, add_json
from app.cli.output import dump_json
from app.cli.progress import progress_bar

#: Exit status of 'verify' when it found something to do.
EXIT_FOUND = 3


def register(sub) -> None:
    p = sub.add_parser("verify", help="check the database, every imported file and every stored result",
                       description="Checks the database (integrity_check), every imported file against the checksum "
                                   "recorded at its import, files the database does not list, every stored result "
                                   "against the checksum stored with it, and whether the results match their "
                                   "inputs. Changes nothing. Each problem is one line with what to do; exit status 3 "
                                   "when there is any.")
    add_dir(p)
    add_json(p)
    p.set_defaults(func=cmd_verify)

    p = sub.add_parser("repair", help="register again the files the database lost; never deletes anything",
                       description="Sets a damaged schema version from the tables; registers again every file in "
                                   "scans/, camera/, environment/ and prediction/ that the database does not list "
                                   "(an older campaign.sqlite restored over a newer folder) when its checksum and "
                                   "header still match its import; reads damaged series again from their files. "
                                   "Damaged results are recomputed by 'process'. Says what it did.")
    add_dir(p)
    add_json(p)
    p.set_defaults(func=cmd_repair)


def cmd_verify(args) -> int:
    from projects.results.integrity import verify_campaign
    from projects.store.campaign import Campaign

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
    from projects.results.integrity import repair_folder

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

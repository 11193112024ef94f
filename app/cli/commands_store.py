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


def _stale(c) -> list:
    """Results that do not match their inputs (processing's view), as findings."""
    from projects.processing.stages import baseline_epoch, stale_epochs
    from projects.store.verify import Finding

    out = [Finding("stale", f"epoch {label}", f"results are stale ({why})", "run 'bridgesurvey process'")
           for label, why in stale_epochs(c).items()]
    base = baseline_epoch(c)
    for e in c.epochs():
        res, ds = c.result(e.label), c.displacement_set(e.label)
        if res is not None and res.stage == "measured" and base is not None and (ds is None or ds.baseline != base):
            out.append(Finding("stale", f"epoch {e.label}", "displacements missing or against another baseline",
                               "run 'bridgesurvey process'"))
    return out


def cmd_verify(args) -> int:
    from projects.store.campaign import Campaign
    from projects.store.verify import verify_store

    with Campaign.open(args.dir, writable=False) as c:
        with progress_bar("verifying") as cb:
            findings = verify_store(c, progress=cb)
        findings += _stale(c)
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


def _reimporters() -> dict:
    """How each kind of series file is read again (with the options of its import, from the journal)."""
    from projects.series.camera import import_series
    from projects.series.environment import import_env
    from projects.series.predictions import import_prediction

    def camera(c, path, e):
        name, _ = import_series(c, path, name=e.get("name"), reflector=e.get("reflector"), **e.get("read", {}))
        return f"{path.parent.name}/{path.name}: camera series {name!r} read again"

    def environment(c, path, e):
        name, _ = import_env(c, path, kind=e["series_kind"], name=e.get("name"), **e.get("read", {}))
        return f"{path.parent.name}/{path.name}: environment series {name!r} read again"

    def prediction(c, path, e):
        targets = import_prediction(c, path, **e.get("read", {}))
        return f"{path.parent.name}/{path.name}: design prediction of {', '.join(sorted(targets))} read again"

    return {"camera": camera, "environment": environment, "prediction": prediction}


def cmd_repair(args) -> int:
    from projects.store.campaign import Campaign
    from projects.store.repair import repair_campaign, repair_schema_version

    schema_note = repair_schema_version(args.dir)
    with Campaign.open(args.dir) as c:
        rep = repair_campaign(c, _reimporters())
    done = ([schema_note] if schema_note else []) + rep.done
    if args.json:
        dump_json({"done": done, "left": rep.left})
    else:
        for line in done:
            print(f"repaired: {line}")
        for line in rep.left:
            print(f"left: {line}")
        print(f"{len(done)} repair(s), {len(rep.left)} left as they are; nothing was deleted"
              + ("; run 'bridgesurvey process' to bring the results up to date" if rep.done else ""))
    return EXIT_FOUND if rep.left else 0

"""The check's verdict on the rows (issue 41): a visit processed without the re-scan its check asked for says so on
the displacement rows of the targets to re-scan, through the command line as a surveyor runs it."""
from __future__ import annotations

import csv
import io

from app.cli.main import main
from common.flags import FLAG_RESCAN_SKIPPED, REGISTRY, WARNING, code
from tests.projects.onsite.test_onsite_check import LABEL, short_visit  # noqa: F401  (fixture)


def _rows(camp, capsys) -> dict[str, list[str]]:
    assert main(["displacements", str(camp), "--format", "csv"]) == 0
    out = capsys.readouterr().out
    return {r["reflector"]: [f.strip() for f in r["flags"].split(";") if f.strip()]
            for r in csv.DictReader(io.StringIO(out)) if r["epoch"] == LABEL}


def test_rows_processed_without_the_rescan_carry_the_checks_verdict(short_visit, capsys):  # noqa: F811
    camp, _ = short_visit
    assert REGISTRY[FLAG_RESCAN_SKIPPED].severity == WARNING and REGISTRY[FLAG_RESCAN_SKIPPED].action
    assert main(["check", str(camp), "--epoch", LABEL]) == 3  # M2 short, M3 not found: re-scan them
    capsys.readouterr()
    assert main(["process", str(camp), "--accept-check"]) in (0, 3)
    capsys.readouterr()
    rows = _rows(camp, capsys)
    skipped = {rid: [f for f in flags if code(f) == FLAG_RESCAN_SKIPPED] for rid, flags in rows.items()}
    assert skipped["M3"] == [f"{FLAG_RESCAN_SKIPPED}: not found"], rows["M3"]
    assert len(skipped["M2"]) == 1 and "planned points" in skipped["M2"][0], rows["M2"]
    assert all(not v for rid, v in skipped.items() if rid not in ("M2", "M3")), skipped
    # processing again changes nothing: the rows keep what the check said
    assert main(["process", str(camp)]) in (0, 3)
    capsys.readouterr()
    assert _rows(camp, capsys) == rows

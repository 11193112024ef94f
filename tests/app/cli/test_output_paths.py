"""One line for every output (and input) path mistake, before any computing (issue 25 item 3).

Each command is given a campaign folder that does not exist: a path mistake must be reported before
the campaign is even opened, so nothing can have been computed (``compare --out EXISTING_FILE`` used to
be refused only after 11 s of work).
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from app.cli.main import main

L = "2026-03-02"
#: command -> argv with {D} (a campaign folder that does not exist), {T} (a scratch folder with dummy inputs)
#: and {OUT} (the output path under test).
FILE_OUTPUTS = {
    "plan --out": "plan {D} --epoch " + L + " --out {OUT}",
    "plan --sheet": "plan {D} --epoch " + L + " --out {T}/plan.json --sheet {OUT}",
    "export": "export {D} --out {OUT}",
    "displacements": "displacements {D} --out {OUT}",
    "field-sheet": "field-sheet {D} --epoch " + L + " --out {OUT}",
    "check": "check {D} --epoch " + L + " --out {OUT}",
    "stations --out": "stations {D} --out {OUT}",
    "stations --png": "stations {D} --out {T}/stations.json --png {OUT}",
    "report": "report {D} --out {OUT}",
    "fleet report": "fleet report {D} --out {OUT}",
    "detect --png": "detect {T}/scan.laz --layout {T}/layout.csv --png {OUT}",
    "plan-file --out": "plan-file {T}/scan.laz --layout {T}/layout.csv --out {OUT}",
    "plan-file --png": "plan-file {T}/scan.laz --layout {T}/layout.csv --out {T}/plan.json --png {OUT}",
    "dualcam calibrate": "dualcam calibrate --zhang {T}/img --main {T}/img --sub {T}/img --pattern {T}/pattern.csv "
                         "--board 4x3 --square-mm 10 --out {OUT}",
    "dualcam measure": "dualcam measure --setup {T}/setup.json --main {T}/img --sub {T}/img --out {OUT}",
}
FOLDER_OUTPUTS = {
    "compare": "compare {D} --from " + L + " --to 2026-03-09 --out {OUT}",
    "analyse": "analyse {D} --out {OUT}",
    "crossval": "crossval {D} --out {OUT}",
    "simulate": "simulate {OUT}",
    "dualcam simulate": "dualcam simulate {OUT}",
    "demo": "demo {OUT}",
}
#: The ending each file output wants (the mistakes are made with a good name).
ENDING = {"plan --sheet": ".pdf", "export": ".xlsx", "field-sheet": ".pdf", "report": ".pdf", "fleet report": ".pdf",
          "stations --png": ".png", "detect --png": ".png", "plan-file --png": ".png"}


@pytest.fixture
def scratch(tmp_path) -> Path:
    t = tmp_path / "t"
    (t / "img").mkdir(parents=True)
    for name in ("scan.laz", "layout.csv", "pattern.csv", "setup.json"):
        (t / name).write_text("dummy\n")
    (t / "a-file").write_text("in the way\n")
    (t / "a-folder").mkdir()
    return t


def _run(template: str, tmp: Path, out: Path, capsys) -> tuple[int, str]:
    argv = template.format(D=tmp / "no-campaign", T=tmp, OUT=out).split()
    code = main(argv)
    err = capsys.readouterr().err.strip()
    return code, err


def _one_line(code: int, err: str, *words: str) -> None:
    assert code == 1, err
    assert len(err.splitlines()) == 1 and err.startswith("bridgesurvey: error: "), err
    for w in words:
        assert w in err, err


@pytest.mark.parametrize("name", sorted(FILE_OUTPUTS))
def test_a_file_output_in_a_missing_folder_a_folder_or_under_a_file_is_refused_first(name, scratch, capsys):
    template, ending = FILE_OUTPUTS[name], ENDING.get(name, ".json")
    cases = [(scratch / "nope" / f"out{ending}", ("nope", "does not exist")),
             (scratch / "a-folder", ("a-folder", "is a folder")),
             (scratch / "a-file" / f"out{ending}", ("a-file", "is a file, not a folder"))]
    for out, words in cases:
        _one_line(*_run(template, scratch, out, capsys), *words)
    assert not (scratch / "no-campaign").exists() and not (scratch / "nope").exists()


@pytest.mark.parametrize("name", sorted(FOLDER_OUTPUTS))
def test_a_folder_output_that_is_a_file_or_inside_one_is_refused_first(name, scratch, capsys):
    template = FOLDER_OUTPUTS[name]
    _one_line(*_run(template, scratch, scratch / "a-file", capsys), "a-file", "is a file, not a folder")
    _one_line(*_run(template, scratch, scratch / "a-file" / "sub", capsys), "a-file", "which is a file")


@pytest.mark.parametrize("name", ["plan --out", "export", "report", "compare", "analyse"])
def test_a_good_output_path_passes_the_check(name, scratch, capsys):
    template = {**FILE_OUTPUTS, **FOLDER_OUTPUTS}[name]
    out = scratch / "new-folder" if name in FOLDER_OUTPUTS else scratch / f"out{ENDING.get(name, '.json')}"
    _one_line(*_run(template, scratch, out, capsys), "no campaign here")  # the next thing looked at
    assert not out.exists()


def test_a_wrong_ending_is_refused_with_the_endings_wanted(scratch, capsys):
    _one_line(*_run(FILE_OUTPUTS["export"], scratch, scratch / "x.doc", capsys), "x.doc", ".xlsx or .csv")
    _one_line(*_run(FILE_OUTPUTS["report"], scratch, scratch / "x.txt", capsys), "x.txt", ".pdf")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
@pytest.mark.parametrize("name", ["plan --out", "export", "report", "analyse", "compare"])
def test_no_write_permission_is_refused_first(name, scratch, capsys):
    locked = scratch / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        template = {**FILE_OUTPUTS, **FOLDER_OUTPUTS}[name]
        out = locked / ("sub" if name in FOLDER_OUTPUTS else f"out{ENDING.get(name, '.json')}")
        _one_line(*_run(template, scratch, out, capsys), "no permission")
    finally:
        locked.chmod(0o700)


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
@pytest.mark.parametrize("name", ["plan --out", "report", "analyse", "compare", "plan-file --out"])
def test_a_place_nobody_may_write_is_refused_first_even_for_root(name, scratch, capsys):
    """/proc takes no new files: os.access tells root it may write there; the check tries instead."""
    template = {**FILE_OUTPUTS, **FOLDER_OUTPUTS}[name]
    out = Path("/proc") / ("bridgesurvey-out" if name in FOLDER_OUTPUTS else f"out{ENDING.get(name, '.json')}")
    _one_line(*_run(template, scratch, out, capsys), str(out), "no permission to write in /proc")
    assert not out.exists() and not (scratch / "no-campaign").exists()


def test_input_paths_say_what_is_wrong_with_them(scratch, capsys):
    d = scratch / "no-campaign"
    _one_line(main(["add-epoch", str(d), "--date", L, "--coarse", str(scratch / "a-folder")]),
              capsys.readouterr().err.strip(), "a-folder", "is a folder, not a file")
    _one_line(main(["add-epoch", str(d), "--date", L, "--coarse", str(scratch / "none.laz")]),
              capsys.readouterr().err.strip(), "none.laz", "no such file")
    _one_line(main(["add-fine", str(d), "--epoch", L, str(scratch / "scan.laz"), str(scratch / "a-folder")]),
              capsys.readouterr().err.strip(), "a-folder", "is a folder")
    _one_line(main(["init", str(d), "--name", "x", "--layout", str(scratch / "a-folder")]),
              capsys.readouterr().err.strip(), "is a folder")
    _one_line(main(["dualcam", "measure", "--setup", str(scratch / "setup.json"), "--main", str(scratch / "a-file"),
                    "--sub", str(scratch / "img"), "--out", str(scratch / "s.csv")]),
              capsys.readouterr().err.strip(), "a-file", "is a file; give the folder")
    assert not d.exists()


@pytest.mark.parametrize("name", ["plan --out", "report", "analyse"])
def test_no_write_permission_is_refused_first_even_for_root(name, scratch, capsys, monkeypatch):
    # root may write anywhere: the check asks the system (os.access); here the system says no
    template = {**FILE_OUTPUTS, **FOLDER_OUTPUTS}[name]
    out = scratch / ("sub" if name in FOLDER_OUTPUTS else f"out{ENDING.get(name, '.json')}")
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != scratch)
    _one_line(*_run(template, scratch, out, capsys), "no permission", str(scratch))

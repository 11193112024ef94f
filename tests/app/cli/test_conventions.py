"""Command-line conventions (issue 25 item 11, issue 27): help everywhere, the order of a visit, the
sub-command's own usage on a mistake, and a parser that imports nothing heavy."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from app.cli.args import DIR_EXPLAINED, DIR_HELP
from app.cli.main import COMMAND_GROUPS, COMMAND_MODULES, _walk, build_parser, main

ROOT = Path(__file__).resolve().parents[3]
#: What building the parser (and refusing a command before it starts) must not import.
HEAVY = ("numpy", "pandas", "scipy", "py4dgeo", "PySide6", "open3d", "matplotlib", "laspy", "dask", "reportlab",
         "cv2", "skimage", "pyvista", "lidar", "projects.store", "vision", "registration")


def _parsers():
    return list(_walk(build_parser()))


def test_every_option_and_command_has_help():
    missing = []
    for path, parser in _parsers():
        name = " ".join(path) or "bridgesurvey"
        if path and not parser.description:
            missing.append(f"{name}: no description")
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if isinstance(action, argparse._SubParsersAction):
                helps = {a.dest: a.help for a in action._choices_actions}
                helps.update(getattr(action, "helps", {}))
                missing += [f"{name} {sub}: no one-line help" for sub in action.choices if not helps.get(sub)]
                continue
            if not action.help or action.help == argparse.SUPPRESS:
                missing.append(f"{name}: {'/'.join(action.option_strings) or action.dest} has no help")
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize("columns", ["50", "80", "200"])
def test_commands_are_listed_once_in_the_order_of_a_visit(columns, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", columns)
    top = build_parser()
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    grouped = [n for _, names in COMMAND_GROUPS for n in names]
    assert sorted(grouped) == sorted(sub.choices), "every command in exactly one group"
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    lines = out.splitlines()
    # a command's line starts with it at 4 spaces; its help's next lines are indented further (any width)
    listed = [ln.split()[0] for ln in lines if ln[:4] == "    " and ln[4:5] != " " and ln.split()[0] in sub.choices]
    assert listed == grouped  # the visit's order, not the alphabet nor the registration order
    assert " ".join(DIR_EXPLAINED.split()) in " ".join(out.split())  # the positional DIR, explained once
    assert "other" not in [ln.strip() for ln in lines]


def test_every_campaign_dir_is_explained_and_epoch_and_json_have_help():
    seen = {"dir": 0, "--epoch": 0, "--json": 0}
    for path, parser in _parsers():
        for action in parser._actions:
            if action.dest == "dir" and not action.option_strings and action.metavar == "DIR":
                assert action.help == DIR_HELP or path == ("demo",), path
                seen["dir"] += 1
            for flag in ("--epoch", "--json"):
                if flag in action.option_strings:
                    assert action.help, (path, flag)
                    seen[flag] += 1
    assert all(n >= 5 for n in seen.values()), seen


@pytest.mark.parametrize("argv, usage", [
    (["process", "DIR", "--epochs", "X"], "usage: bridgesurvey process"),
    (["status", "DIR", "--everything"], "usage: bridgesurvey status"),
    (["fleet", "status", "ROOT", "--jsn"], "usage: bridgesurvey fleet status"),
    (["reflector", "list", "DIR", "--bogus"], "usage: bridgesurvey reflector list"),
])
def test_a_mistake_shows_the_usage_of_its_own_command(argv, usage, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(usage) and "unrecognized arguments" in err
    if argv[0] == "process":
        assert "did you mean --epoch?" in err


@pytest.mark.parametrize("command, wanted, unwanted", [
    ("check", "+30 %)", "%%"),
    ("plan", "Find and identify the targets", None),
    ("env import", "temperature, structure-temperature", None),
])
def test_command_help_reads_well(command, wanted, unwanted, capsys):
    with pytest.raises(SystemExit):
        main(command.split() + ["--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert wanted in out
    assert unwanted is None or unwanted not in out


def _modules_after(code: str) -> dict:
    probe = ("import json, sys\n" + code + "\nprint('@@' + json.dumps(sorted(m for m in sys.modules if m.split('.')[0] "
             "in {h.split('.')[0] for h in " + repr(HEAVY) + "})))")
    res = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True)
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("@@"))
    return {"loaded": json.loads(line[2:]), "stderr": res.stderr}


def _heavy(loaded: list[str]) -> list[str]:
    return [m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY)]


def test_building_the_parser_imports_nothing_heavy():
    r = _modules_after("from app.cli.main import build_parser\nbuild_parser()")
    assert _heavy(r["loaded"]) == [], r


def test_help_and_a_refused_command_import_nothing_heavy(tmp_path):
    r = _modules_after("from app.cli.main import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass")
    assert _heavy(r["loaded"]) == [], r
    out = tmp_path / "nope" / "plan.json"
    r = _modules_after(f"from app.cli.main import main\nrc = main(['plan', {str(tmp_path)!r}, '--epoch', 'x', "
                       f"'--out', {str(out)!r}])\nassert rc == 1, rc")
    assert _heavy(r["loaded"]) == [], r
    assert "does not exist" in r["stderr"] and len(r["stderr"].strip().splitlines()) == 1


def test_status_of_a_processed_campaign_leaves_the_coarse_analysis_unloaded(processed):
    """`status` reads the campaign: the coarse analysis's scikit-image and SciPy are 0.3-0.6 s of its start-up."""
    r = _modules_after(f"from app.cli.main import main\nrc = main(['status', {str(processed)!r}])\nassert rc == 0, rc")
    assert "projects.store.campaign" in r["loaded"], r  # the probe saw the campaign read
    assert [m for m in _heavy(r["loaded"]) if m.split(".")[0] in ("scipy", "skimage", "pandas")] == [], r


def test_no_help_breaks_a_word_at_its_hyphen(monkeypatch):
    import re

    monkeypatch.setenv("COLUMNS", "64")
    broken = []
    for path, parser in _parsers():
        text = parser.format_help()
        broken += [f"{' '.join(path)}: {m.group(0)!r}" for m in re.finditer(r"\w+-\n", text)]
    assert not broken, broken


def test_every_path_option_of_another_module_is_found_and_checked():
    from app.cli.args import path_kind
    from app.cli.main import FOREIGN_PATHS

    parsers = {path: p for path, p in _parsers()}
    for (command, dest), kind in FOREIGN_PATHS.items():
        actions = [a for a in parsers[(command,)]._actions if a.dest == dest]
        assert len(actions) == 1 and path_kind(actions[0]) == kind, (command, dest)


def test_every_output_option_is_checked():
    from app.cli.args import path_kind

    unchecked = [f"{' '.join(path)} {a.dest}" for path, p in _parsers() for a in p._actions
                 if a.dest in ("out", "png", "sheet", "output") and path_kind(a) is None]
    assert not unchecked, unchecked


@pytest.mark.parametrize("command, single", [("info", True), ("status", False)])
def test_file_commands_load_numpy_with_a_single_threaded_blas(tmp_path, command, single):
    """OpenBLAS's idle pool spins a core after numpy loads: the file commands, whose loops are their own, skip it."""
    pytest.importorskip("threadpoolctl")
    target = ROOT / "tests" / "data" / "las" / "simple.las" if command == "info" else tmp_path
    probe = (f"from app.cli.main import main\nmain([{command!r}, {str(target)!r}])\nimport numpy, threadpoolctl\n"
             "print('@@', [i['num_threads'] for i in threadpoolctl.threadpool_info() if i['internal_api'] == 'openblas'])")
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    res = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, env=env)
    threads = json.loads(next(ln for ln in res.stdout.splitlines() if ln.startswith("@@"))[3:])
    assert threads, res.stderr  # numpy's wheels carry OpenBLAS
    assert (threads == [1]) == single or (not single and os.cpu_count() == 1), threads


def test_each_command_is_parsed_by_its_own_modules_parser_alone():
    """A command on the line builds only its module's parser (COMMAND_MODULES): the table must say true."""
    full = {path[0]: p for path, p in _walk(build_parser()) if len(path) == 1}
    assert set(full) == set(COMMAND_MODULES) == {n for _, names in COMMAND_GROUPS for n in names}
    for command, module in COMMAND_MODULES.items():
        alone = {path[0]: p for path, p in _walk(build_parser(command)) if len(path) == 1}
        assert command in alone
        assert {c for c, m in COMMAND_MODULES.items() if m == module} == set(alone)
        assert alone[command].format_help() == full[command].format_help()


def test_the_program_exits_with_the_commands_status(tmp_path, monkeypatch, capsys):
    import gc

    from app.cli.main import run

    monkeypatch.setattr(sys, "argv", ["bridgesurvey", "status", str(tmp_path / "nowhere")])
    try:
        with pytest.raises(SystemExit) as stop:
            run()
    finally:
        gc.unfreeze()  # run() freezes the survivors for a quick exit; this process goes on
    assert stop.value.code == 1 and "no campaign here" in capsys.readouterr().err


def test_every_command_names_a_function_of_its_group_module():
    """Each parser's ``func`` is a function of app.cli.commands_GROUP, imported only when the command runs."""
    import importlib

    named = [(path, p.get_default("func")) for path, p in _parsers() if p.get_default("func")]
    assert len(named) >= len(COMMAND_MODULES)
    for path, func in named:
        module = importlib.import_module(f"app.cli.commands_{COMMAND_MODULES[path[0]]}")
        assert callable(getattr(module, func, None)), (path, func)

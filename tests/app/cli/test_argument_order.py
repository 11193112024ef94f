"""One argument order for every command with actions (issue 41 item 5): COMMAND ACTION DIR, the other order read
the same with a one-line note, never "invalid choice"."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from app.cli.main import _walk, action_first, build_parser, main


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "app.cli.main", *map(str, args)], capture_output=True, text=True)


def _commands_with_actions() -> list[tuple[str, list[str]]]:
    top = build_parser()
    sub = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction))
    found = []
    for name, parser in sub.choices.items():
        actions = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        if actions is not None:
            found.append((name, list(actions.choices)))
    return found


def test_every_command_with_actions_takes_the_action_first():
    found = dict(_commands_with_actions())
    assert {"reflector", "env", "event", "prediction", "camera", "fleet", "dualcam"} <= set(found)
    parsers = dict(_walk(build_parser()))
    for command, actions in found.items():
        for action in actions:
            parser = parsers[(command, action)]
            assert parser.format_usage().startswith(f"usage: bridgesurvey {command} {action}")
            positional = [a.dest for a in parser._actions if not a.option_strings]
            folders = [i for i, dest in enumerate(positional) if dest in ("dir", "roots")]
            assert folders in ([], [0]), (command, action, positional)  # the folder right after the action


@pytest.mark.parametrize("command, actions", _commands_with_actions())
def test_the_other_order_is_read_with_a_note_never_invalid_choice(command, actions, capsys):
    parser = build_parser(command)
    for action in actions:
        assert action_first(parser, [command, "FOLDER", action, "--json"]) == [command, action, "FOLDER", "--json"]
        note = capsys.readouterr().err
        assert note.count("\n") == 1 and f"bridgesurvey {command} {action} FOLDER --json" in note
        with pytest.raises(SystemExit) as exc:
            main([command, "FOLDER", action, "--help"])
        assert exc.value.code == 0
        out = capsys.readouterr()
        assert "invalid choice" not in out.err and out.out.startswith(f"usage: bridgesurvey {command} {action}")
    # the contract order is left alone, and so is a real mistake (an action that does not exist)
    assert action_first(parser, [command, actions[0], "FOLDER"]) == [command, actions[0], "FOLDER"]
    assert action_first(parser, [command, "FOLDER", "nope"]) == [command, "FOLDER", "nope"]
    assert capsys.readouterr().err == ""


def test_reflector_and_env_in_both_orders_on_a_campaign(processed_copy):
    r = _cli("reflector", "list", processed_copy, "--json")
    assert r.returncode == 0 and r.stderr == "", r.stderr
    ids = [row["id"] for row in json.loads(r.stdout)]
    assert "M3" in ids
    r = _cli("reflector", processed_copy, "list", "--json")
    assert r.returncode == 0, r.stderr
    assert [row["id"] for row in json.loads(r.stdout)] == ids
    assert r.stderr.strip() == f"bridgesurvey: note: the action comes first: bridgesurvey reflector list " \
                               f"{processed_copy} --json"
    r = _cli("env", processed_copy, "list")
    assert r.returncode == 0 and "the action comes first: bridgesurvey env list" in r.stderr
    r = _cli("fleet", processed_copy, "status")
    assert r.returncode == 0 and "bridges" in r.stdout.lower() + r.stderr.lower(), r.stdout + r.stderr
    r = _cli("reflector", "retire", processed_copy, "Q7", "--date", "2026-05-01")
    assert r.returncode == 1 and r.stderr.strip().splitlines() == [
        "bridgesurvey: error: unknown reflector 'Q7'; the campaign has R1, R2, R3, R4, M1, M2, M3, M4, M5"]

"""A long job in a process of its own (common.processes.run_in_process): result, progress, errors, cancel."""
from __future__ import annotations

import os
import signal
import time

import pytest

from common.errors import CancelledError, InputError, SurveyError
from common.processes import run_in_process


def counted(n: int, *, progress) -> tuple[int, int]:
    for k in range(n):
        progress(k / n, f"step {k}")
    return n, os.getpid()


def refused(name: str, *, progress) -> None:
    progress(0.5, "reading")
    raise InputError(f"{name}: not a scan file")


class Unpicklable(SurveyError):
    def __init__(self, a, b):  # two arguments: pickle rebuilds it with one (its message) and fails
        super().__init__(f"{a} and {b}")


def refused_oddly(*, progress) -> None:
    raise Unpicklable("one", "two")


def forever(marker: str, *, progress) -> None:
    while True:
        progress(0.1, "working")
        with open(marker, "a") as f:
            f.write(".")
        time.sleep(0.05)


def killed(*, progress) -> None:
    os.kill(os.getpid(), signal.SIGKILL)


def test_the_result_and_the_progress_come_back_from_another_process():
    seen = []
    n, pid = run_in_process(counted, 5, progress=lambda f, m: seen.append((f, m)))
    assert n == 5 and pid != os.getpid()
    # in order ("starting" until the child's first word, and the last word again while it is quiet)
    assert list(dict.fromkeys(m for _, m in seen if m.startswith("step"))) == [f"step {k}" for k in range(5)]
    assert all(m.startswith("step") or m == "starting" for _, m in seen)


def test_an_error_comes_back_with_its_message_and_type():
    with pytest.raises(InputError, match="x.laz: not a scan file"):
        run_in_process(refused, "x.laz")
    with pytest.raises(SurveyError, match="one and two"):  # one that pickle cannot rebuild: its message
        run_in_process(refused_oddly)


def test_a_cancel_stops_the_child(tmp_path):
    marker = tmp_path / "ticks"
    calls = []

    def progress(fraction, message):
        calls.append(message)
        if calls.count("working") >= 3:  # the child is at work (its start-up takes a second)
            raise CancelledError()

    with pytest.raises(CancelledError):
        run_in_process(forever, str(marker), progress=progress)
    size = marker.stat().st_size
    time.sleep(0.5)
    assert marker.stat().st_size == size  # the child has stopped writing


def test_a_child_killed_without_a_word_is_one_line():
    with pytest.raises(SurveyError, match="worker process stopped"):
        run_in_process(killed)

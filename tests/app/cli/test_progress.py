"""Long commands show progress: lines when stderr is not a terminal, nothing for quick ones."""
from app.cli.progress import progress_bar


def test_progress_lines_when_not_a_terminal(capsys):
    with progress_bar("demo campaign", interval_s=0.0) as cb:
        for w in range(3):
            cb(w / 3, f"week {w + 1}/3")
        cb(1.0, "done")
    err = capsys.readouterr().err.splitlines()
    assert err == ["demo campaign:   0% week 1/3", "demo campaign:  33% week 2/3", "demo campaign:  67% week 3/3",
                   "demo campaign: 100% done"]


def test_a_quick_command_prints_no_progress(capsys):
    with progress_bar("processing", interval_s=60.0) as cb:
        cb(0.5, "epoch 1")
        cb(1.0, "done")
    with progress_bar("report", enabled=False) as cb:
        cb(0.5, "maps")
    assert capsys.readouterr().err == ""

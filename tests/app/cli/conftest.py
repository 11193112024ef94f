"""The campaign fixtures of tests/projects, for the command-line tests, and reading their stderr."""
import re

from tests.projects.conftest import field, field_copy, processed, processed_copy  # noqa: F401  (fixtures)

#: A progress line of app.cli.progress when stderr is not a terminal ('calibration frames:  20% frame 3 of 15').
PROGRESS_LINE = re.compile(r"^[^:]+: +\d{1,3}%( |$)")


def error_lines(err: str) -> list[str]:
    """stderr without progress lines: a command slower than the progress interval (a busy machine) prints some."""
    return [ln for ln in err.strip().splitlines() if not PROGRESS_LINE.match(ln)]

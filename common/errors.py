"""The project's exception hierarchy.

Every error BridgeSurvey raises on purpose derives from :class:`SurveyError`.
The command line and the desktop application catch ``SurveyError`` and show its
message (one line: what went wrong, where, and what to do next); anything else
reaching them is a bug.
"""
from __future__ import annotations

import os


class SurveyError(Exception):
    """Root of all BridgeSurvey errors."""


class InputError(SurveyError, ValueError):
    """An argument or value given by the user or a caller is not acceptable."""


class ScanFormatError(SurveyError):
    """A scan file cannot be read: unsupported, corrupt, truncated or empty."""

    def __init__(self, path: str | os.PathLike, problem: str):
        self.path = os.fspath(path)
        # Damaged files put control characters into quoted fragments: keep the message one printable line.
        self.problem = "".join(c if c.isprintable() else "?" for c in problem)
        problem = self.problem
        super().__init__(f"{self.path}: {problem}")


class ProcessingError(SurveyError):
    """Processing cannot produce a trustworthy result from the data given."""


class CancelledError(SurveyError):
    """The user cancelled a long-running operation."""

    def __init__(self, message: str = "cancelled by the user"):
        super().__init__(message)

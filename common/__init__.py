"""The shared kernel every domain package builds on.

The exception root (``errors``), progress callbacks (``progress``), atomic output files (``files``), rigid transforms
(``rigid``) and argument
checks (``validation``). It imports nothing of BridgeSurvey's own.
"""

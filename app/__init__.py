"""The BridgeSurvey command line (``app.cli``) and desktop application (``app.gui``).

Thin layers over :mod:`projects`, :mod:`registration`, :mod:`vision` and :mod:`lidar`.
Only this package imports Qt.
"""

"""A matplotlib canvas for Qt views."""
from __future__ import annotations

from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure


class PlotCanvas(FigureCanvasQTAgg):
    """A Figure in a widget; ``figure`` is redrawn by the view that owns it."""

    def __init__(self, parent=None, *, figsize=(8, 5)):
        super().__init__(Figure(figsize=figsize, layout="constrained"))
        self.setParent(parent)

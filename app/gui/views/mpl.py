"""A matplotlib canvas for Qt views."""
from __future__ import annotations

from matplotlib.backends.backend_qtagg import FigureCanvasQTAgg
from matplotlib.figure import Figure


class PlotCanvas(FigureCanvasQTAgg):
    """A Figure in a widget; ``figure`` is redrawn by the view that owns it.

    A canvas that is not shown (its tab is not the current one) draws when it is shown, not at each change:
    a figure takes a few tenths of a second to draw on the interface thread, and a processed visit changes
    every view at once.
    """

    def __init__(self, parent=None, *, figsize=(8, 5)):
        super().__init__(Figure(figsize=figsize, layout="constrained"))
        self.setParent(parent)
        self.pending = False  # changed while hidden: to draw when shown

    def draw_idle(self) -> None:
        if not self.isVisible():
            self.pending = True
            return
        self.pending = False
        super().draw_idle()

    def showEvent(self, event):  # noqa: N802
        super().showEvent(event)
        if self.pending:
            self.draw_idle()

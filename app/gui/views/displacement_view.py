"""Displacement histories: one target or all, with ±2σ bars, warning and alarm lines, hover values,
and a click that selects the epoch."""
from __future__ import annotations

import matplotlib.dates as mdates
import numpy as np
from PySide6.QtCore import Signal
from PySide6.QtWidgets import QCheckBox, QComboBox, QHBoxLayout, QLabel, QVBoxLayout, QWidget

from app.gui.views.mpl import PlotCanvas
from app.gui.widgets import ElidedLabel
from projects.series.context import draw_context

#: Above this many points drawn the legend goes to a fixed corner instead of the least crowded place.
BEST_LEGEND_POINTS = 1000


class DisplacementView(QWidget):
    """Emits ``epochPicked(label)`` when the user clicks a point."""
    epochPicked = Signal(str)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.canvas = PlotCanvas(self, figsize=(9, 5))
        self.target = QComboBox()
        self.target.setSizeAdjustPolicy(QComboBox.AdjustToContents)
        self.target.setMinimumContentsLength(len("all targets") + 1)
        self.target.setToolTip("One target's history, or every target's")
        self.target.currentTextChanged.connect(lambda _t: self.redraw())
        self.limits = QCheckBox("limit lines")
        self.limits.setChecked(True)
        self.limits.toggled.connect(lambda _b: self.redraw())
        self.context_box = QCheckBox("events and temperature")
        self.context_box.setChecked(True)
        self.context_box.toggled.connect(lambda _b: self.redraw())
        self.context = None
        self.hover = ElidedLabel(" ", min_chars=8)
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Target"))
        bar.addWidget(self.target)
        bar.addWidget(self.limits)
        bar.addWidget(self.context_box)
        bar.addWidget(self.hover, 1)
        lay = QVBoxLayout(self)
        lay.addLayout(bar)
        lay.addWidget(self.canvas, 1)
        self.histories: dict = {}
        self.selected_epoch = None
        self._points = []  # (x, y, history, index) drawn, for hover and picking
        self._annot = None  # the hover label of the current plot
        self._stale = False  # changed while hidden: redrawn when shown
        self.canvas.mpl_connect("motion_notify_event", self._on_move)
        self.canvas.mpl_connect("button_press_event", self._on_click)

    def show_snapshot(self, snap) -> None:
        """Draw the histories of an :class:`app.gui.state.app_state.Snapshot`."""
        self.set_data(snap.histories, snap.context)

    def show_selection(self, sel) -> None:
        """Follow the selected target and epoch (an :class:`app.gui.state.app_state.Selection`)."""
        if sel.reflector and self.target.findText(sel.reflector) >= 0 and self.target.currentText() != sel.reflector:
            self.target.blockSignals(True)
            self.target.setCurrentText(sel.reflector)
            self.target.blockSignals(False)
        self.select_epoch(sel.epoch)

    def set_data(self, histories: dict, context=None) -> None:
        """``histories`` from :func:`projects.history.histories` (reflector -> DisplacementHistory, with
        its limits); ``context`` a :class:`projects.context.PlotContext` (events, an environment series) or None."""
        self.histories = histories
        self.context = context
        targets = sorted(histories)
        current = self.target.currentText()
        self.target.blockSignals(True)
        self.target.clear()
        self.target.addItems(["all targets"] + targets)
        if current in targets:
            self.target.setCurrentText(current)
        self.target.blockSignals(False)
        self.redraw()

    def show_target(self, rid: str) -> None:
        if self.target.findText(rid) >= 0:
            self.target.setCurrentText(rid)

    def select_epoch(self, label) -> None:
        self.selected_epoch = label
        self.redraw()

    def _draw_events(self, ax) -> None:
        """Event lines with horizontal labels along the top, staggered so that neighbours do not overlap."""
        events = sorted(self.context.events) if self.context is not None else []
        lo, hi = ax.get_xlim()
        last_end = [-np.inf, -np.inf, -np.inf]  # per row: where the previous label ends (axes fraction)
        for when, label in events:
            x = mdates.date2num(when)
            if not lo <= x <= hi:
                continue
            frac = (x - lo) / (hi - lo)
            width = 0.0085 * len(label) + 0.01
            row = next((k for k, end in enumerate(last_end) if frac > end), len(last_end) - 1)
            last_end[row] = frac + width
            right = frac + width > 0.98  # near the right edge: the label goes left of its line
            ax.annotate(label, (x, 1.0), xycoords=("data", "axes fraction"), xytext=(-3 if right else 3, -4 - 12 * row),
                        textcoords="offset points", ha="right" if right else "left", va="top", fontsize=7,
                        color="tab:purple", bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))

    def showEvent(self, event):  # noqa: N802
        super().showEvent(event)
        if self._stale:
            self.redraw()

    def redraw(self) -> None:
        if not self.isVisible():  # drawn when its tab is shown: building the plot holds the interface a while
            self._stale = True
            return
        self._stale = False
        fig = self.canvas.figure
        fig.clear()
        ax = fig.add_subplot(111)
        self._points = []
        self._annot = None
        which = self.target.currentText()
        targets = sorted(self.histories) if which in ("", "all targets") else [which]
        if not self.histories:
            ax.text(0.5, 0.5, "No displacements yet: add epochs and process them", ha="center", va="center",
                    transform=ax.transAxes)
            ax.set_axis_off()
            self.canvas.draw_idle()
            return
        colours = {t: f"C{k % 10}" for k, t in enumerate(sorted(self.histories))}
        for rid in targets:
            h = self.histories[rid].measured() if rid in self.histories else None
            if h is None or not len(h):
                continue
            x, y = list(h.times), h.displacement_mm
            ax.errorbar(x, y, yerr=2 * h.sigma_mm, fmt="o-", ms=3.5, lw=1, capsize=2, color=colours[rid], label=rid)
            flagged = np.flatnonzero(h.flagged)
            if flagged.size:
                ax.plot([x[i] for i in flagged], y[flagged], "o", ms=9, mfc="none", mec="red")
            self._points += [(x[i], y[i], h, i) for i in range(len(h))]
        if self.limits.isChecked():
            drawn = set()
            ys = [p[1] for p in self._points]
            reach = 2.0 * max((abs(v) for v in ys), default=0.0) + 1.0
            for rid in targets:
                lim = self.histories[rid].limit if rid in self.histories else None
                if lim is None or (lim.warning_mm, lim.alarm_mm) in drawn:
                    continue
                drawn.add((lim.warning_mm, lim.alarm_mm))
                hidden = []
                for v, colour, name in ((lim.warning_mm, "orange", "warning"), (lim.alarm_mm, "red", "alarm")):
                    if v is None:
                        continue
                    if v <= reach:  # limits far beyond the data are named, not drawn: the data stay readable
                        for sgn in (-1, 1):
                            ax.axhline(sgn * v, color=colour, ls="--", lw=1)
                    else:
                        hidden.append(name)
                ax.text(0.01, 0.02, f"limits: warning ±{lim.warning_mm:.1f} mm, alarm ±{lim.alarm_mm:.1f} mm "
                                    f"({lim.rule})" + (f"; {' and '.join(hidden)} off the scale" if hidden else ""),
                        transform=ax.transAxes, fontsize=8, color="0.3")
        if self.selected_epoch:
            sel = [p for p in self._points if p[2].epochs[p[3]] == self.selected_epoch]
            if sel:
                ax.axvline(sel[0][0], color="0.4", lw=1, ls=":")
        self._annot = ax.annotate("", xy=(0, 0), xytext=(12, 12), textcoords="offset points", fontsize=8,
                                  bbox=dict(boxstyle="round", fc="lightyellow", alpha=0.9), visible=False)
        ax.set_ylabel("vertical displacement (mm, positive up)")
        ax.set_title("Displacement history (±2σ)" + ("" if len(targets) > 1 else f" of {targets[0]}"))
        ax.grid(alpha=0.3)
        # 'best' tries every place against every point drawn: 0.25 s at 180 visits of 9 targets, growing with them
        ax.legend(loc="best" if len(self._points) <= BEST_LEGEND_POINTS else "upper left", fontsize=8, ncol=2)
        self._ax = ax
        if self.context_box.isChecked() and self.context is not None:
            draw_context(ax, self.context, label_events=False)  # the lines; horizontal labels below
            self._draw_events(ax)
        fig.autofmt_xdate()
        self.canvas.draw_idle()

    def _nearest(self, event):
        if event.inaxes is None or not self._points:
            return None
        ax = self._ax  # the displacement axes (an environment series lives on a twin axes above it)
        pix = ax.transData.transform([(ax.convert_xunits(p[0]), p[1]) for p in self._points])
        d = np.hypot(pix[:, 0] - event.x, pix[:, 1] - event.y)
        k = int(np.argmin(d))
        return self._points[k] if d[k] < 10 else None

    def _on_move(self, event) -> None:
        p = self._nearest(event)
        if p is None:
            if self._annot is not None and self._annot.get_visible():
                self._annot.set_visible(False)
                self.canvas.draw_idle()
            return
        h, i = p[2], p[3]
        flags = ", ".join(h.flags[i])
        text = (f"{h.reflector} {h.epochs[i]}: {h.displacement_mm[i]:+.3f} ± {h.sigma_mm[i]:.3f} mm"
                + (f" [{flags}]" if flags else ""))
        self.hover.setText(text)
        self._annot.xy = (p[0], p[1])
        self._annot.set_text(text)
        self._annot.set_visible(True)
        self.canvas.draw_idle()

    def _on_click(self, event) -> None:
        p = self._nearest(event)
        if p is not None:
            self.epochPicked.emit(p[2].epochs[p[3]])

"""The campaign tree: the structure, its reflectors by group, its epochs by date with their state.

An epoch's state is the one :func:`projects.results.state.epoch_state` decides (through
``campaign_status``, the same as ``bridgesurvey status`` and the report print): imported, planned,
scanned, measured, processed (plain text), or — processed with a flag that asks the surveyor to act or makes the
result untrustworthy — ``warning`` (orange, a warning sign) or ``problem`` (red, bold, a stop sign): only what
needs action is coloured. Their flags and what they mean are in the tooltip.
"""
from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor, QFont
from PySide6.QtWidgets import QHeaderView, QStyle, QTreeWidget, QTreeWidgetItem

from common.flags import describe

STATE_COLOURS = {"imported": "#7f7f7f", "planned": "#1f77b4", "scanned": "#9467bd", "measured": "#17becf",
                 "processed": "#2ca02c", "problem": "#c00000", "ok": "#2ca02c", "warning": "#d46b08",
                 "alarm": "#c00000", "unknown": "#7f7f7f", "retired": "#7f7f7f"}
#: States that need the surveyor's look, with the standard icon that marks them.
MARKED = {"warning": QStyle.SP_MessageBoxWarning, "problem": QStyle.SP_MessageBoxCritical,
          "alarm": QStyle.SP_MessageBoxCritical}
KIND = Qt.UserRole
KEY = Qt.UserRole + 1


class CampaignTree(QTreeWidget):
    """Emits ``picked(kind, key)`` when the user selects an item (kind: campaign, reflector, epoch, series)
    and ``activated_item(kind, key)`` on a double click."""
    picked = Signal(str, str)
    activated_item = Signal(str, str)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setHeaderLabels(["Campaign", "State"])
        header = self.header()
        header.setStretchLastSection(False)
        header.setSectionResizeMode(0, QHeaderView.ResizeToContents)
        header.setSectionResizeMode(1, QHeaderView.ResizeToContents)
        self.setHorizontalScrollBarPolicy(Qt.ScrollBarAsNeeded)
        self.setMinimumWidth(200)
        self.setIndentation(16)
        self.itemSelectionChanged.connect(self._on_selection)
        self.itemDoubleClicked.connect(lambda it, _col: self.activated_item.emit(it.data(0, KIND) or "",
                                                                                  it.data(0, KEY) or ""))
        self._items: dict[tuple[str, str], QTreeWidgetItem] = {}

    def _item(self, parent, text: str, state: str = "", kind: str = "", key: str = "", tip: str = "", *,
              shown_state: str = ""):
        it = QTreeWidgetItem(parent, [text, shown_state or state])
        it.setData(0, KIND, kind)
        it.setData(0, KEY, key)
        if state in MARKED:  # colour only what needs action (issue 38): the other states are plain text
            it.setIcon(1, self.style().standardIcon(MARKED[state]))
            it.setForeground(0, QBrush(QColor(STATE_COLOURS[state])))
            it.setForeground(1, QBrush(QColor(STATE_COLOURS[state])))
        if state in ("problem", "alarm"):
            bold = QFont(self.font())
            bold.setBold(True)
            it.setFont(0, bold)
            it.setFont(1, bold)
        if tip:
            it.setToolTip(0, tip)
            it.setToolTip(1, tip)
        if kind:
            self._items[(kind, key)] = it
        return it

    # ------------------------------------------------------------------ what the state says
    def show_snapshot(self, snap) -> None:
        """Rebuild from an :class:`app.gui.state.app_state.Snapshot`."""
        self.populate(snap.status, snap.reflectors, snap.series)

    def show_selection(self, sel) -> None:
        """Select the item the details show (an :class:`app.gui.state.app_state.Selection`)."""
        self.select_key(*sel.focus)

    def populate(self, status: dict, reflectors, series) -> None:
        """Rebuild from :func:`projects.results.status.campaign_status`, the reflectors and the camera series."""
        selected = self.current_key()
        self.blockSignals(True)
        self.clear()
        self._items.clear()
        span = f", {status['span_m']:g} m span" if status.get("span_m") else ""
        self._item(self, "Overview", "", "campaign", "", f"{status['name']}{span}: the campaign's details")
        latest = {t["reflector"]: t for t in status["targets"]}
        for group, title in (("reference", "Reference (piers)"), ("measurement", "Measurement (deck)")):
            rows = [r for r in reflectors if r.group == group]
            g = self._item(self, f"{title}, {len(rows)}")
            for r in rows:
                t = latest.get(r.id)
                state = "retired" if r.retired else (t["state"] if t else "")
                text = r.id
                if t and t["displacement_mm"] is not None:
                    text += f"   {t['displacement_mm']:+.2f} mm"
                flags = t["flags"] if t and t["flags"] else ""
                self._item(g, text, state, "reflector", r.id, (r.note or "") + (f" flags: {flags}" if flags else ""))
        self._epochs(self, status["epochs"])
        if series:
            cam = self._item(self, f"Camera series ({len(series)})")
            for s in series:
                self._item(cam, s.name, s.reflector or "", "series", s.name,
                           f"{s.summary['rows']} rows, {s.summary['start'][:10]} .. {s.summary['end'][:10]}")
        self.expandAll()
        self.blockSignals(False)
        if selected in self._items:
            self.setCurrentItem(self._items[selected])

    def _epochs(self, root, epochs: list[dict]) -> None:
        marked = [e for e in epochs if e["state"] in ("warning", "problem")]
        counts = {s: sum(e["state"] == s for e in marked) for s in ("warning", "problem")}
        summary = ", ".join(f"{n} {s}{'s' if n > 1 else ''}" for s, n in counts.items() if n)
        eps = self._item(root, f"Epochs ({len(epochs)}" + (f"; {summary}" if summary else "") + ")",
                         "problem" if counts["problem"] else ("warning" if counts["warning"] else ""))
        for e in epochs:
            flags = e.get("flag_list") or []
            parts = []
            if e["stale"]:
                parts.append(f"to process: {e['stale']}")
            if flags:
                parts.append(describe(flags))
            self._item(eps, e["epoch"], e["state"], "epoch", e["epoch"], "\n".join(parts),
                       shown_state=e["state"] + (" *" if e["stale"] else ""))

    # ------------------------------------------------------------------ keys
    def current_key(self):
        it = self.currentItem()
        return None if it is None else (it.data(0, KIND) or "", it.data(0, KEY) or "")

    def select_key(self, kind: str, key: str) -> None:
        it = self._items.get((kind, key))
        if it is not None and it is not self.currentItem():
            self.setCurrentItem(it)
            self.scrollToItem(it)

    def item_for(self, kind: str, key: str):
        return self._items.get((kind, key))

    def _on_selection(self) -> None:
        k = self.current_key()
        if k is not None and k[0]:
            self.picked.emit(*k)

"""The campaign tree: the structure, its reflectors by group, its epochs by date with their state."""
from __future__ import annotations

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import QTreeWidget, QTreeWidgetItem

STATE_COLOURS = {"imported": "#7f7f7f", "planned": "#1f77b4", "scanned": "#9467bd", "measured": "#17becf",
                 "processed": "#2ca02c", "problem": "#d62728", "ok": "#2ca02c", "warning": "#ff7f0e",
                 "alarm": "#d62728", "unknown": "#7f7f7f"}
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
        self.setColumnWidth(0, 200)
        self.itemSelectionChanged.connect(self._on_selection)
        self.itemDoubleClicked.connect(lambda it, _col: self.activated_item.emit(it.data(0, KIND) or "",
                                                                                  it.data(0, KEY) or ""))
        self._items: dict[tuple[str, str], QTreeWidgetItem] = {}

    def _item(self, parent, text: str, state: str = "", kind: str = "", key: str = "", tip: str = ""):
        it = QTreeWidgetItem(parent, [text, state])
        it.setData(0, KIND, kind)
        it.setData(0, KEY, key)
        if state in STATE_COLOURS:
            it.setForeground(1, QBrush(QColor(STATE_COLOURS[state])))
        if tip:
            it.setToolTip(0, tip)
            it.setToolTip(1, tip)
        if kind:
            self._items[(kind, key)] = it
        return it

    def populate(self, status: dict, reflectors: list, series: list) -> None:
        """Rebuild from :func:`projects.overview.campaign_status`, the reflectors and the camera series."""
        selected = self.current_key()
        self.blockSignals(True)
        self.clear()
        self._items.clear()
        span = f", {status['span_m']:g} m span" if status.get("span_m") else ""
        root = self._item(self, status["name"], "", "campaign", "", f"{status['name']}{span}")
        latest = {t["reflector"]: t for t in status["targets"]}
        refl = self._item(root, f"Reflectors ({len(reflectors)})")
        for group, title in (("reference", "Reference group (piers)"), ("measurement", "Measurement group (deck)")):
            rows = [r for r in reflectors if r.group == group]
            g = self._item(refl, f"{title} ({len(rows)})")
            for r in rows:
                t = latest.get(r.id)
                state = "retired" if r.retired else (t["state"] if t else "")
                text = r.id
                if t and t["displacement_mm"] is not None:
                    text += f"   {t['displacement_mm']:+.2f} mm"
                self._item(g, text, state, "reflector", r.id, (r.note or "") + (f" flags: {t['flags']}"
                                                                                       if t and t["flags"] else ""))
        eps = self._item(root, f"Epochs ({len(status['epochs'])})")
        for e in status["epochs"]:
            tip = "; ".join(x for x in (e["stale"] and f"to process: {e['stale']}", e["flags"]) if x)
            self._item(eps, f"{e['epoch']}", e["state"] + (" *" if e["stale"] else ""), "epoch", e["epoch"], tip)
        if series:
            cam = self._item(root, f"Camera series ({len(series)})")
            for s in series:
                self._item(cam, s.name, s.reflector or "", "series", s.name,
                           f"{s.summary['rows']} rows, {s.summary['start'][:10]} .. {s.summary['end'][:10]}")
        self.expandToDepth(2)
        self.blockSignals(False)
        if selected in self._items:
            self.setCurrentItem(self._items[selected])

    def current_key(self):
        it = self.currentItem()
        return None if it is None else (it.data(0, KIND) or "", it.data(0, KEY) or "")

    def select_key(self, kind: str, key: str) -> None:
        it = self._items.get((kind, key))
        if it is not None and it is not self.currentItem():
            self.setCurrentItem(it)

    def item_for(self, kind: str, key: str):
        return self._items.get((kind, key))

    def _on_selection(self) -> None:
        k = self.current_key()
        if k is not None and k[0]:
            self.picked.emit(*k)

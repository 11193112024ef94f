"""The state of a campaign at a glance: every epoch's stage and every target's latest displacement.

Shared by ``bridgesurvey status`` and the desktop application's campaign tree.
"""
from __future__ import annotations

import json

from projects.store import Campaign

#: Epoch stages, in the order work moves them along.
EPOCH_STATES = ("imported", "planned", "scanned", "measured", "processed", "flagged")


def epoch_state(c: Campaign, label: str) -> tuple[str, list[str]]:
    """(state, flags) of one epoch: imported (coarse scan only), planned, scanned (fine scans not
    measured yet), measured, processed (displacements computed) or flagged (processed with flags)."""
    res = c.result_row(label)
    ds = c.displacement_set(label)
    if ds is not None:
        flags = json.loads(ds["flags"])
        return ("flagged" if flags else "processed"), flags
    if res is None:
        return "imported", []
    if res["stage"] == "planned":
        return ("scanned" if c.files(label, "fine") else "planned"), []
    return "measured", []


def campaign_status(c: Campaign) -> dict:
    """Name, span, baseline, epochs (state, staleness, flags) and the latest row of every target."""
    from projects.exports import displacement_table
    from projects.processing import baseline_epoch, stale_epochs

    stale = stale_epochs(c)
    epochs = []
    for e in c.epochs():
        state, flags = epoch_state(c, e["label"])
        epochs.append({"epoch": e["label"], "datetime": e["datetime"][:16], "state": state,
                       "stale": stale.get(e["label"], ""), "flags": ",".join(flags)})
    latest = {}
    for r in displacement_table(c):
        latest[r["reflector"]] = r
    return {"name": c.name, "span_m": c.span_m, "baseline": baseline_epoch(c), "epochs": epochs,
            "targets": list(latest.values())}

"""The next step of a weekly visit, from the campaign's state (no Qt here).

A visit goes: add the epoch (its coarse scan) → plan the fine scans → scan and add the fine scans →
check them before leaving → process → report. The application shows the step that comes next for
the selected epoch (else the latest) as a button, so a surveyor never has to guess.

>>> eps = [{"epoch": "e1", "state": "processed", "stale": ""}, {"epoch": "e2", "state": "imported", "stale": "new"}]
>>> next_step({"epochs": eps}, None).command
'plan'
>>> next_step({"epochs": eps}, "e1").command  # e1 is done, but e2 still waits
'plan'
>>> next_step({"epochs": []}, None).text
'Next: add the first epoch'
>>> checked = {"epoch": "e2", "state": "measured", "stale": "new", "rescan": ["M3"], "check": "re-scan M3"}
>>> next_step({"epochs": [eps[0], checked]}, None).text  # the check asked for a re-scan: that comes first
'Next: re-scan M3 of e2'
"""
from __future__ import annotations

from dataclasses import dataclass

#: The commands a next step can be, with the menu entry that does the same (for tooltips).
MENU = {"add_epoch": "Epoch ▸ Add epoch…", "plan": "Epoch ▸ Plan the selected epoch",
        "add_fine": "Epoch ▸ Add fine scans to the selected epoch…",
        "check": "Epoch ▸ Check the fine scans before leaving", "process": "Epoch ▸ Process",
        "report": "Reports ▸ Write report (PDF)…"}


@dataclass(frozen=True)
class NextStep:
    """What to do next: ``command`` (a key of :data:`MENU`), the button text, and the epoch it is for."""

    command: str
    text: str
    epoch: str | None = None
    why: str = ""

    @property
    def tooltip(self) -> str:
        return f"{self.why} (also {MENU[self.command]})" if self.why else f"Also {MENU[self.command]}"


def _for_epoch(e: dict) -> NextStep | None:
    label, state = e["epoch"], e["state"]
    if state == "imported":
        return NextStep("plan", f"Next: plan {label}", label,
                        f"{label} has its coarse scan: plan the fine-scan windows for the scanner")
    if state == "planned":
        return NextStep("add_fine", f"Next: add the fine scans of {label}", label,
                        f"{label} is planned: scan the windows, then add the fine-scan files")
    if state == "scanned":
        return NextStep("check", f"Next: check {label} before leaving", label,
                        f"{label} has fine scans: check that every target got enough points before leaving the site")
    if e.get("rescan"):  # the check is binding: its re-scan comes before processing
        names = ", ".join(e["rescan"])
        return NextStep("add_fine", f"Next: re-scan {names} of {label}", label,
                        f"the check of {label} asked: {e.get('check')}; scan the re-scan plan and add its files "
                        "(processing it as it is asks first)")
    if state == "measured" or e.get("stale"):
        return NextStep("process", "Next: process", label, f"{label} is measured: compute its displacements")
    return None


def next_step(status: dict, selected_epoch: str | None) -> NextStep:
    """The next step for ``selected_epoch`` (or, when it has none left, the first epoch with work left).

    ``status`` is :func:`projects.results.status.campaign_status` (its ``epochs``: ``epoch``, ``state``,
    ``stale``).
    """
    epochs = status.get("epochs", [])
    if not epochs:
        return NextStep("add_epoch", "Next: add the first epoch", None,
                        "import the coarse scan of the first visit")
    chosen = [e for e in epochs if e["epoch"] == selected_epoch]
    for e in chosen + list(reversed(epochs)):
        step = _for_epoch(e)
        if step is not None:
            return step
    return NextStep("report", "Next: write the report", None, "every epoch is processed: write the report, or "
                                                              "add the next visit (Epoch ▸ Add epoch…)")

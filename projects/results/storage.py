"""Which visits' scans may leave the campaign folder: the fully processed ones (see :mod:`projects.store.archive`).

A visit is fully processed when every set-up of it is measured with its current inputs and parameters (not
stale) and its displacements are stored and up to date: its scans are then needed again only when a stage-1
parameter changes, or for the whole-scan comparison, the 3-D view and the inspection of a target.
"""
from __future__ import annotations

import datetime as dt

from projects.processing.stages import stale_displacements, stale_epochs
from projects.store.archive import is_here
from projects.store.campaign import Campaign


def archivable_epochs(c: Campaign, before: dt.datetime | None = None) -> tuple[list[str], dict[str, str]]:
    """(the fully processed epochs dated before ``before`` with scans in the folder, the others with scans: why not).

    Both in date order; epochs dated ``before`` or later, and those whose scans are all archived, are in neither.
    """
    stale = stale_epochs(c)
    stale2 = stale_displacements(c)
    ok, left = [], {}
    for e in c.epochs():
        if before is not None and e.when >= before:
            continue
        files = c.files(e.label, setup=None)
        if not any(is_here(c, f) for f in files):
            continue
        unmeasured = [k for k in c.setups(e.label) if (r := c.result(e.label, k)) is None or r.stage != "measured"]
        if e.label in stale:
            left[e.label] = f"stage 1 not up to date ({stale[e.label]}): run 'bridgesurvey process' first"
        elif unmeasured:
            left[e.label] = ("not measured yet" if unmeasured == [1] else
                             f"set-up(s) {', '.join(map(str, unmeasured))} not measured yet")
        elif c.displacement_set(e.label) is None or e.label in stale2:
            left[e.label] = f"displacements not up to date ({stale2.get(e.label, 'not computed')}): run 'process' first"
        else:
            ok.append(e.label)
    return ok, left

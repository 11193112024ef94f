"""The state of a campaign at a glance: every epoch's stage and every target's latest displacement.

Shared by ``bridgesurvey status`` and the desktop application's campaign tree.
"""
from __future__ import annotations

from common.flags import FLAG_REFERENCE_AMBIGUOUS, count, worst
from projects.store.campaign import Campaign

#: Epoch stages, in the order work moves them along; the last three are processed epochs by the
#: most serious flag they carry (see :mod:`common.flags`): none or information only, a warning, a problem.
EPOCH_STATES = ("imported", "planned", "scanned", "measured", "processed", "warning", "problem")


def epoch_flags(c: Campaign, label: str) -> list[str]:
    """The epoch's own flags, then its targets' (each distinct flag once).

    An ambiguous reference change names its suspects.
    """
    ds = c.displacement_set(label)
    if ds is None:
        return []
    flags = list(ds.flags)
    if FLAG_REFERENCE_AMBIGUOUS in flags:
        suspects = [r.reflector for r in c.reference_checks(label) if r.suspect]
        if suspects:
            flags[flags.index(FLAG_REFERENCE_AMBIGUOUS)] = \
                f"{FLAG_REFERENCE_AMBIGUOUS}: {' or '.join(suspects)} moved (both left out)"
    for f in c.displacement_flags(label):
        if f not in flags:
            flags.append(f)
    return flags


def epoch_state(c: Campaign, label: str) -> tuple[str, list[str]]:
    """(state, flags) of one epoch.

    The state is imported (coarse scan only), planned, scanned (fine scans not
    measured yet), measured, or - once its displacements are computed - processed, warning or
    problem by its most serious flag.
    """
    res = c.result(label)
    ds = c.displacement_set(label)
    if ds is not None:
        flags = epoch_flags(c, label)
        level = worst(flags)
        return (level if level in ("warning", "problem") else "processed"), flags
    if res is None:
        return "imported", []
    if res.stage == "planned":
        return ("scanned" if c.files(label, "fine") else "planned"), []
    return "measured", []


def campaign_status(c: Campaign) -> dict:
    """Name, span, baseline, epochs (state, staleness, flags), the latest row of every target, and warnings.

    ``warnings`` are the layout's (targets no station could reach) and the stored results that fail their
    checksum (not shown, recomputed by ``process``); ``unlisted_files`` the files of the
    import folders the database does not list (never deleted: ``bridgesurvey repair`` registers them).
    """
    from projects.results.table import displacement_table
    from projects.processing.stages import baseline_epoch, stale_epochs

    stale = stale_epochs(c)
    epochs = []
    for e in c.epochs():
        state, flags = epoch_state(c, e.label)
        epochs.append({"epoch": e.label, "datetime": e.datetime[:16], "state": state,
                       "stale": stale.get(e.label, ""), "flags": "; ".join(flags), "flag_list": flags,
                       "severity": count(flags)})
    from projects.store.verify import REMEDY, describe_group

    damaged = [f"stored {describe_group(t, k)}: damaged (fails its checksum), not shown; {REMEDY[t]}"
               for t, k in c.damaged_results()]
    latest = {}
    for r in displacement_table(c):
        if r["displacement_mm"] is not None or r["reflector"] not in latest:  # keep the last good value
            latest[r["reflector"]] = r
    return {"name": c.name, "span_m": c.span_m, "baseline": baseline_epoch(c), "epochs": epochs,
            "targets": list(latest.values()), "warnings": c.layout_warnings() + damaged,
            "unlisted_files": c.unlisted_files()}

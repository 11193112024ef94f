"""A campaign's status at a glance: what ``bridgesurvey status``, the report and the application's tree show.

Apart from :mod:`projects.results.state` (an epoch's state from its flags), which the displacement table
(:mod:`projects.results.table`) needs, while the status needs the table.
"""
from __future__ import annotations

import math

from common.flags import count
from projects.processing.stages import baseline_epoch, stale_displacements, stale_epochs
from projects.results.corrections import epoch_corrections, instrument_summary
from projects.results.state import epoch_states
from projects.results.table import displacement_table
from projects.store.archive import storage_summary
from projects.store.campaign import Campaign
from projects.store.verify import REMEDY, describe_group


def campaign_status(c: Campaign) -> dict:
    """Name, span, time zone, baseline, epochs, instrument, the latest row of every target, and warnings.

    ``epochs`` carry their state, staleness and flags, the on-site check's verdict (``check``, None when none
    holds) and the targets it asks to re-scan (``rescan``, empty once the re-scan is added or accepted);
    ``instrument`` is the campaign's range walk and axis
    errors as its field model found them (:func:`~projects.results.corrections.instrument_summary`; None
    before one is fitted).

    ``revisions`` are the stored values the last processing that changed any changed (time, and each
    revision's epoch, target, old, new and why; :class:`lidar.stage2.Revision`), None when none ever did.

    ``warnings`` are the layout's (targets no station could reach) and the stored results that fail their
    checksum (not shown, recomputed by ``process``), the map previews left out (pictures, nine tenths of a long
    campaign's bytes: ``verify`` and ``process`` read them); ``unlisted_files`` the files of the
    import folders the database does not list (never deleted: ``bridgesurvey repair`` registers them).
    ``storage`` is the folder's size on disk and where its scans are
    (:func:`projects.store.archive.storage_summary`).
    """
    damaged = [f"stored {describe_group(t, k)}: damaged (fails its checksum), not shown; {REMEDY[t]}"
               for t, k in c.damaged_results(pictures=False)]  # first, a table at a time; previews: verify, process
    stale = stale_epochs(c)
    for label, why in stale_displacements(c).items():  # what processing will recompute, known before it runs
        stale.setdefault(label, why)
    states = epoch_states(c)
    verdicts = c.check_verdicts()
    epochs = []
    for e in c.epochs():
        s = states[e.label]
        corr = epoch_corrections(c.systematics(e.label))
        verdict = verdicts.get(e.label)
        epochs.append({"epoch": e.label, "datetime": e.datetime[:16], "state": s.state,
                       "check": None if verdict is None else verdict.line() + (" (processed as it is, by choice)"
                                                                               if verdict.accepted else ""),
                       "rescan": list(verdict.rescan) if verdict is not None and verdict.asks_rescan else [],
                       "stale": stale.get(e.label, ""), "flags": "; ".join(s.flags), "flag_list": list(s.flags),
                       "severity": count(s.flags),
                       "scale_ppm": None if corr is None else round(corr.scale_ppm, 2) + 0.0,
                       "scale_sigma_ppm": None if corr is None else round(corr.scale_sigma_ppm, 2) + 0.0,
                       "drift_arcsec_h": None if corr is None or not corr.timed
                       else round(math.hypot(corr.tilt_arcsec_h, corr.twist_arcsec_h), 1) + 0.0})
    latest = {}
    for r in displacement_table(c, states=states):
        if r["displacement_mm"] is not None or r["reflector"] not in latest:  # keep the last good value
            latest[r["reflector"]] = r
    last = c.last_revisions()
    revised = None if last is None else {"time": last.time, "revised": last.details.get("revised", [])}
    fitted = c.field_model()
    return {"name": c.name, "span_m": c.span_m, "timezone": c.timezone, "baseline": baseline_epoch(c), "epochs": epochs,
            "instrument": None if fitted is None else instrument_summary(fitted[0]),
            "targets": list(latest.values()), "warnings": c.layout_warnings() + damaged,
            "unlisted_files": c.unlisted_files(), "revisions": revised, "storage": storage_summary(c)}


def storage_line(storage: dict) -> str:
    """The campaign's size on disk and where its scans are, in one line (:func:`campaign_status`'s ``storage``).

    What ``bridgesurvey status`` prints and the application's campaign page shows.

    >>> storage_line({"size_bytes": 885_000_000, "scans_here": 3, "scans_archived": {"/mnt/a": 2}})
    'storage: 885.0 MB on disk; 3 scan(s) in the campaign folder, 2 archived in /mnt/a'
    """
    where = ", ".join(f"{n} archived in {folder}" for folder, n in storage["scans_archived"].items())
    return (f"storage: {storage['size_bytes'] / 1e6:.1f} MB on disk; {storage['scans_here']} scan(s) in the campaign "
            f"folder" + (f", {where}" if where else ""))

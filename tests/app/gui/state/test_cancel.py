"""Cancelling the application's long jobs: the progress callback raises, the work stops at once.

(How fast is measured, not tested: see the report of issue 25; here only that the loops do stop.)
"""
from __future__ import annotations

import multiprocessing
import time

import pytest

from app.gui import actions
from app.gui.state.campaign_access import CampaignAccess
from common.errors import CancelledError
from projects.store.campaign import Campaign


def cancel_after(n: int, seen: list):
    """A progress callback that cancels at its ``n``-th call."""
    def progress(fraction, message=""):
        seen.append(message)
        if len(seen) >= n:
            raise CancelledError()
    return progress


def test_a_cancelled_processing_run_stops_instead_of_failing_every_epoch(processed_copy):
    access = CampaignAccess(processed_copy)
    actions.set_parameter(access, "min_points", "1100")  # every epoch stale
    seen: list = []
    with pytest.raises(CancelledError):
        actions.process(access, cancel_after(3, seen))
    assert len(seen) == 3  # nothing ran after the cancel (it used to go on with the next epoch)
    with Campaign.open(processed_copy, writable=False) as c:
        assert c.displacement_set("2026-03-16") is not None  # the displacements were not recomputed half-way


@pytest.mark.slow
def test_a_cancelled_station_survey_stops_its_workers(processed_copy):
    access = CampaignAccess(processed_copy)
    seen: list = []

    def progress(fraction, message=""):
        seen.append(message)
        if "stations" in message and len(seen) > 1:
            raise CancelledError()

    with pytest.raises(CancelledError):
        actions.stations(access, 2.0, 1.5, progress)
    deadline = time.monotonic() + 10.0
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not multiprocessing.active_children()  # no worker left computing
    assert not any(m.startswith(("600 of", "stations evaluated")) for m in seen)

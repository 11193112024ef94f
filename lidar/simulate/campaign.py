"""Simulated campaigns: a bridge, many visits with their conditions and stations, a layout with design errors.

:func:`write_campaign` writes ``ROOT/layout.csv``, ``ROOT/campaign.json`` (an index: every visit's folder, date,
stations and conditions) and one folder per visit holding ``coarse.laz``, ``fine.laz``, ``truth.json`` and
``scene.json`` (or ``setup1/``, ``setup2/``... with those when a visit has several set-ups). The fine windows
come from a plan callback ``plan_for(visit_folder, coarse_path) -> list of RoiPlan``, so the product's own
planner can be plugged in; :func:`~lidar.simulate.visits.truth_plan_for` plans from the truth.

:func:`random_station` puts a scanner on either side of the bridge, beside any span or near either end;
:func:`random_conditions` draws a visit's effects (span displacements, thermal strain, atmosphere, range walk,
clipping, drift), so every effect of the simulator turns up in a campaign.
"""
from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from common.errors import InputError
from lidar.layout import Layout, layout_from_model, write_layout_csv
from lidar.simulate.bridge import BridgeModel, model_to_dict
from lidar.simulate.effects import (
    DriftModel,
    ExponentialStrengthWalk,
    InverseSquareWalk,
    LinearIncidenceWalk,
    LogisticStrengthWalk,
    RangeWalk,
    StrengthStepWalk,
    VisitTiming,
)
from lidar.simulate.files import conditions_to_dict
from lidar.simulate.scene import EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.visits import PlanFor, PlanVisit, simulate_setups, simulate_visit

CAMPAIGN_FORMAT_VERSION = 1


def random_station(model: BridgeModel, rng: np.random.Generator, *, distance_m: tuple[float, float] = (8.0, 25.0),
                   height_m: tuple[float, float] = (1.2, 1.8), end_fraction: float = 0.3,
                   tilt_deg: float = 0.01) -> ScannerSetup:
    """A scanner set-up on either side of the bridge: beside any span, or (``end_fraction`` of them) near an end.

    Parameters
    ----------
    model : BridgeModel
    rng : numpy Generator
    distance_m : (min, max), keyword-only
        Distance from the deck's edge across the bridge, metres. Default 8-25 m.
    height_m : (min, max), keyword-only
        Instrument height above ground, metres. Default 1.2-1.8 m.
    end_fraction : float, keyword-only
        Share of stations within 5 m inside to 15 m beyond an end pier (else anywhere between the end piers).
        Default 0.3.
    tilt_deg : float, keyword-only
        Standard deviation of the levelling error (pitch, roll), degrees. Default 0.01.

    Returns
    -------
    ScannerSetup, bridge frame, heading uniform in [0, 360).
    """
    if not 0.0 <= end_fraction <= 1.0:
        raise InputError(f"end_fraction must lie in [0, 1], got {end_fraction}")
    side = rng.choice([-1.0, 1.0])
    length = model.length_m
    if rng.uniform() < end_fraction:
        x = rng.uniform(-15.0, 5.0) if rng.uniform() < 0.5 else length + rng.uniform(-5.0, 15.0)
    else:
        x = rng.uniform(0.0, length)
    y = side * (model.deck_width_m / 2 + rng.uniform(*distance_m))
    return ScannerSetup((float(x), float(y), float(rng.uniform(*height_m))), heading_deg=float(rng.uniform(0, 360)),
                        pitch_deg=float(rng.normal(0.0, tilt_deg)), roll_deg=float(rng.normal(0.0, tilt_deg)))


def _random_walk(rng: np.random.Generator, max_bias_m: float) -> RangeWalk:
    """One of the five range-walk forms with a random amplitude up to ``max_bias_m`` (at 15 m head-on)."""
    a = float(rng.uniform(0.2, 1.0)) * max_bias_m
    forms: list[RangeWalk] = [
        LinearIncidenceWalk(a), InverseSquareWalk(2 * a, 15.0), StrengthStepWalk(a, 0.15 * a, float(rng.uniform(0.3, 0.8))),
        LogisticStrengthWalk(a, float(rng.uniform(0.3, 0.8)), 0.15),
        ExponentialStrengthWalk(a / (1 - np.exp(-2.0)), 0.5),
    ]
    return forms[int(rng.integers(len(forms)))]


def random_conditions(model: BridgeModel, rng: np.random.Generator, *, sag_m: tuple[float, float] = (-0.008, 0.0),
                      temperature_c: tuple[float, float] = (-15.0, 15.0), expansion_per_c: float = 12e-6,
                      ppm: tuple[float, float] = (-30.0, 30.0), max_walk_m: float | None = 0.0015,
                      clipped_fraction: tuple[float, float] = (0.0, 0.3), drift_arcsec_per_h: float = 20.0,
                      start_s: float = 0.0, gap_s: float = 30.0) -> EpochConditions:
    """A visit's state with every effect drawn at random (uniform in the ranges given).

    Parameters
    ----------
    model : BridgeModel
    rng : numpy Generator
    sag_m : (min, max), keyword-only
        Midspan displacement of each span, metres (positive up). Default -8..0 mm.
    temperature_c : (min, max), keyword-only
        Deck temperature against the baseline, degC; strain = ``expansion_per_c`` times it. Default -15..15.
    expansion_per_c : float, keyword-only
        Thermal expansion coefficient, 1/degC. Default 12e-6 (concrete, steel).
    ppm : (min, max), keyword-only
        Atmospheric range scale, ppm. Default -30..30.
    max_walk_m : float or None, keyword-only
        Largest range walk at 15 m head-on, metres (a random form each visit); None for none. Default 1.5 mm.
    clipped_fraction : (min, max), keyword-only
        Share of clipped target points. Default 0..0.3.
    drift_arcsec_per_h : float, keyword-only
        Standard deviation of each drift rate, arcsec/h (0: no drift). Default 20.
    start_s, gap_s : float, keyword-only
        Visit timing: first point's time and the gap between scans, seconds. Defaults 0 and 30.

    Returns
    -------
    EpochConditions (timed).
    """
    rates = rng.normal(0.0, drift_arcsec_per_h, 3) if drift_arcsec_per_h > 0 else np.zeros(3)
    return EpochConditions(
        span_displacements_m=tuple(float(v) for v in rng.uniform(*sag_m, model.n_spans)),
        deck_strain=float(expansion_per_c * rng.uniform(*temperature_c)),
        range_scale_ppm=float(rng.uniform(*ppm)),
        range_walk=None if max_walk_m is None else _random_walk(rng, max_walk_m),
        clipped_fraction=float(rng.uniform(*clipped_fraction)),
        drift=DriftModel(*(float(v) for v in rates)) if np.any(rates) else None,
        timing=VisitTiming(start_s=start_s, gap_s=gap_s),
    )


def campaign_layout(model: BridgeModel, *, noise_m: float = 0.03, rng: np.random.Generator | None = None,
                    with_normals: bool = False) -> Layout:
    """The model's targets as a layout with design-drawing errors (``noise_m`` per axis, default 3 cm)."""
    return layout_from_model(model, noise_m=noise_m, rng=rng or np.random.default_rng(0), with_normals=with_normals)


def write_layout(model: BridgeModel, path: str | os.PathLike, *, noise_m: float = 0.03,
                 rng: np.random.Generator | None = None, with_normals: bool = False) -> Path:
    """Write the model's ``layout.csv`` with a few centimetres of error (see :func:`campaign_layout`)."""
    return write_layout_csv(campaign_layout(model, noise_m=noise_m, rng=rng, with_normals=with_normals), path)


@dataclass(frozen=True)
class CampaignVisit:
    """One visit of a written campaign: its folder (relative to the root), date and set-ups."""

    folder: str
    date: str
    setups: tuple[ScannerSetup, ...]
    conditions: EpochConditions


def write_campaign(root: str | os.PathLike, model: BridgeModel, visits: Sequence[EpochConditions], *,
                   plan_for: PlanFor, stations: Sequence[Sequence[ScannerSetup]] | None = None,
                   setups_per_visit: int = 1, seed: int = 0, coarse_step_deg: float = 0.04,
                   start: dt.datetime | None = None, interval_days: float = 7.0, layout_noise_m: float = 0.03,
                   with_normals: bool = False, plan_visit: PlanVisit | None = None) -> list[CampaignVisit]:
    """Write a simulated campaign under ``root`` (see the module text for the files).

    Parameters
    ----------
    root : path-like
    model : BridgeModel
    visits : sequence of EpochConditions
        Each visit's state (e.g. from :func:`random_conditions`), in date order.
    plan_for : callable, keyword-only
        ``plan_for(visit_folder, coarse_path) -> list of RoiPlan`` for each set-up.
    stations : sequence of sequences of ScannerSetup, optional, keyword-only
        The set-ups of each visit. Default: ``setups_per_visit`` random stations a visit (:func:`random_station`).
    setups_per_visit : int, keyword-only
        Set-ups per visit when the stations are drawn. Default 1 (the files straight in the visit folder).
    seed : int, keyword-only
        Seeds the stations, the layout errors and each visit's noise. Default 0.
    coarse_step_deg : float, keyword-only
        Coarse scan step. Default 0.04 deg.
    start : datetime, optional, keyword-only
        First visit's date. Default 2026-01-05 09:00 UTC.
    interval_days : float, keyword-only
        Days between visits. Default 7.
    layout_noise_m : float, keyword-only
        Error of the layout's coordinates, per axis, metres. Default 0.03.
    with_normals : bool, keyword-only
        Whether the layout gives the targets' normals. Default False.
    plan_visit : callable, optional, keyword-only
        ``plan_visit(setup_folders, coarse_paths) -> windows of each set-up``: a visit of several set-ups is
        planned together, once all its coarse scans are taken (:func:`lidar.simulate.visits.simulate_setups`).
        Default: each set-up planned by ``plan_for`` in turn.

    Returns
    -------
    list of CampaignVisit, as indexed in ``campaign.json``.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    write_layout(model, root / "layout.csv", noise_m=layout_noise_m, rng=rng, with_normals=with_normals)
    if stations is not None and len(stations) != len(visits):
        raise InputError(f"{len(visits)} visits but stations for {len(stations)}")
    start = start or dt.datetime(2026, 1, 5, 9, 0, tzinfo=dt.UTC)
    out = []
    for k, cond in enumerate(visits):
        setups = tuple(stations[k]) if stations is not None else \
            tuple(random_station(model, rng) for _ in range(setups_per_visit))
        folder = f"visit{k + 1:03d}"
        if len(setups) == 1:
            simulate_visit(root / folder, setup=setups[0], conditions=cond, plan_for=plan_for, model=model,
                           seed=seed * 1000 + k, coarse_step_deg=coarse_step_deg)
        else:
            simulate_setups(root / folder, setups, cond, plan_for=plan_for, model=model, seed=seed * 1000 + k,
                            coarse_step_deg=coarse_step_deg, plan_visit=plan_visit)
        date = (start + dt.timedelta(days=interval_days * k)).isoformat()
        out.append(CampaignVisit(folder, date, setups, cond))
    _write_index(root, model, out)
    return out


def _write_index(root: Path, model: BridgeModel, visits: Sequence[CampaignVisit]) -> Path:
    index = {"format_version": CAMPAIGN_FORMAT_VERSION, "model": model_to_dict(model), "layout": "layout.csv",
             "visits": [{"folder": v.folder, "date": v.date, "setups": [asdict(s) for s in v.setups],
                         "conditions": conditions_to_dict(v.conditions)} for v in visits]}
    p = root / "campaign.json"
    p.write_text(json.dumps(index, indent=1))
    return p

"""Simulated campaigns processed exactly like real ones and scored against their truth (benchmarks, tests).

:func:`run_study` writes a campaign of visits with :func:`lidar.simulate.campaign.write_campaign`, planning
every visit's fine scans with the product's own planner (the coarse scan imported into a campaign and
planned, as a surveyor would on site), imports the fine scans, processes, and compares every reported
displacement, along-span movement and scale with the simulator's truth. :class:`StudyScore` says how far
the errors are from zero and from their sigmas, and how many are beyond 3 sigma without a warning on their
own row.

A visit of several set-ups (``stations`` with two or more per visit) is imported as a surveyor would:
``add-epoch`` with the first set-up's coarse scan, ``add-setup`` with each further one's, each set-up
planned and its fine scans added to it; with ``coarse_first`` every coarse scan of the visit is imported before
the set-ups are planned (together when the settings say ``plan_together true``).
"""
from __future__ import annotations

import datetime as dt
import json
import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from common.errors import SurveyError
from common.flags import FLAG_ATMOSPHERE_DISAGREES, FLAG_PIER_MOVED, PROBLEM, WARNING, code, severity
from lidar.layout import read_layout_csv
from lidar.plan import ScanPlan
from lidar.simulate.bridge import BridgeModel
from lidar.simulate.campaign import write_campaign
from lidar.simulate.scene import EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth
from projects.processing.stages import plan_epoch, process, set_parameter
from projects.series.environment import import_env
from projects.store.campaign import Campaign

START = dt.datetime(2026, 1, 5, 9, 0, tzinfo=dt.UTC)


def _within(errors: list, sigmas: list, k: float) -> float:
    """Share of errors within ``k`` sigma (NaN without any)."""
    e, s = np.abs(errors), np.asarray(sigmas)
    return float(np.mean(e <= k * s)) if e.size else float("nan")


def _silent(errors: list, sigmas: list, warned: list) -> float:
    """Share of errors beyond 3 sigma whose row carries no warning or problem flag (NaN without any)."""
    e, s, w = np.abs(errors), np.asarray(sigmas), np.asarray(warned, dtype=bool)
    return float(np.mean((e > 3 * s) & ~w)) if e.size else float("nan")


@dataclass
class StudyScore:
    """Errors of every reported value against the truth (millimetres, ppm)."""

    errors_mm: list = field(default_factory=list)
    sigmas_mm: list = field(default_factory=list)
    warned: list = field(default_factory=list)  # the row itself carries a warning or a problem flag
    visit_numbers: list = field(default_factory=list)  # each error's visit, counted from 1 (the baseline) in date order
    along_errors_mm: list = field(default_factory=list)
    along_sigmas_mm: list = field(default_factory=list)
    along_warned: list = field(default_factory=list)  # the along-span movement's row carries a warning or problem
    scale_errors_ppm: list = field(default_factory=list)
    scale_sigmas_ppm: list = field(default_factory=list)
    reference_flags: list = field(default_factory=list)  # (epoch, flag) of reference-check flags raised
    scale_flags: list = field(default_factory=list)  # (epoch, flag): the scale disagreeing with the air, a pier moved
    missing: int = 0
    expected: int = 0
    refused: dict = field(default_factory=dict)  # epoch -> the line planning refused it with

    @property
    def rms_mm(self) -> float:
        e = np.asarray(self.errors_mm, dtype=float)
        return float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan")

    @property
    def max_mm(self) -> float:
        return float(np.max(np.abs(self.errors_mm))) if self.errors_mm else float("nan")

    @property
    def within_2sigma(self) -> float:
        return _within(self.errors_mm, self.sigmas_mm, 2.0)

    def first_visits(self, n: int) -> StudyScore:
        """The displacements of the campaign's first ``n`` visits only (the baseline one of them)."""
        keep = [k for k, v in enumerate(self.visit_numbers) if v <= n]
        return StudyScore([self.errors_mm[k] for k in keep], [self.sigmas_mm[k] for k in keep],
                          [self.warned[k] for k in keep], [self.visit_numbers[k] for k in keep])

    @property
    def silent_beyond_3sigma(self) -> float:
        """Share of displacements off by more than 3 sigma with no warning or problem flag on their own row."""
        return _silent(self.errors_mm, self.sigmas_mm, self.warned)

    @property
    def along_silent_beyond_3sigma(self) -> float:
        """Share of along-span movements off by more than 3 sigma with no warning or problem flag on their row."""
        return _silent(self.along_errors_mm, self.along_sigmas_mm, self.along_warned)

    @property
    def along_within_2sigma(self) -> float:
        return _within(self.along_errors_mm, self.along_sigmas_mm, 2.0)

    @property
    def along_bad(self) -> float:
        """Share of along-span movements off by more than max(3 sigma, 0.3 mm)."""
        e, s = np.abs(self.along_errors_mm), np.asarray(self.along_sigmas_mm)
        return float(np.mean(e > np.maximum(3 * s, 0.3))) if e.size else float("nan")

    @property
    def scale_max_ppm(self) -> float:
        return float(np.max(np.abs(self.scale_errors_ppm))) if self.scale_errors_ppm else float("nan")

    @property
    def scale_within_2sigma(self) -> float:
        """Share of the visits' scales within 2 sigma of the truth (NaN without any)."""
        return _within(self.scale_errors_ppm, self.scale_sigmas_ppm, 2.0)

    def row(self) -> dict:
        return {"rms_mm": self.rms_mm, "max_mm": self.max_mm, "within_2sigma": self.within_2sigma,
                "silent_beyond_3sigma": self.silent_beyond_3sigma, "along_bad": self.along_bad,
                "along_within_2sigma": self.along_within_2sigma,
                "along_silent_beyond_3sigma": self.along_silent_beyond_3sigma,
                "scale_max_ppm": self.scale_max_ppm, "scale_within_2sigma": self.scale_within_2sigma,
                "reference_flags": len(self.reference_flags), "scale_flags": len(self.scale_flags),
                "measured": f"{self.expected - self.missing}/{self.expected}"}


class ProductPlanner:
    """The ``plan_for`` callback of :func:`lidar.simulate.campaign.write_campaign`: plans with the product."""

    def __init__(self, campaign_dir: Path, layout_csv: Path, *, span_m: float | None,
                 settings: dict | None = None):
        self.dir, self.layout_csv, self.span_m = campaign_dir, layout_csv, span_m
        self.settings = settings or {}
        self.count = 0
        self.labels: dict[Path, str] = {}
        self.refused: dict[str, str] = {}  # epoch -> the line planning refused it with
        self.fine_imported: set[Path] = set()  # set-up folders whose fine scans are imported

    def _import(self, folder: Path, coarse: Path) -> tuple[str, int]:
        """A set-up's coarse scan imported as a surveyor would: (epoch, set-up)."""
        if not (self.dir / "campaign.sqlite").exists():
            with Campaign.create(self.dir, name="study", layout=read_layout_csv(self.layout_csv),
                                 span_m=self.span_m) as c:
                for k, v in self.settings.items():
                    set_parameter(c, k, str(v))
        setup = _setup_number(Path(folder))
        with Campaign.open(self.dir) as c:
            if setup > 1:  # another station of the visit: add it to that epoch
                label = self.labels[Path(folder).parent / "setup1"]
                self.labels[Path(folder)] = label
                self.import_fine(c, [Path(folder).parent / f"setup{k}" for k in range(1, setup)])
                (setup,) = c.add_setup(label, coarse)
            else:
                when = START + dt.timedelta(days=7 * self.count)
                label = f"v{self.count + 1:03d}"
                self.count += 1
                self.labels[Path(folder)] = label
                c.add_epoch(label, when.isoformat(), coarse)
        return label, setup

    def import_fine(self, c: Campaign, folders) -> None:
        """The fine scans of set-ups already worked, imported as on site.

        Each set-up's before the next one's coarse scan (``add-fine`` before ``add-setup``), so that planning
        together finds their plans frozen.
        """
        for f in folders:
            fine = Path(f) / "fine.laz"
            if f in self.labels and f not in self.fine_imported and fine.exists():
                c.import_files(self.labels[f], [fine], "fine", setup=_setup_number(Path(f)))
                self.fine_imported.add(Path(f))

    def __call__(self, folder: Path, coarse: Path) -> list:

        label, setup = self._import(Path(folder), Path(coarse))
        with Campaign.open(self.dir) as c:
            try:
                plan: ScanPlan = plan_epoch(c, label, setup=setup)
            except SurveyError as exc:
                self.refused[label] = str(exc).splitlines()[0]
                return []
        return list(plan.rois)


    def plan_visit(self, folders: Sequence[Path], coarse: Sequence[Path]) -> list[list]:
        """The ``plan_visit`` callback: a visit's coarse scans imported, then each set-up planned.

        Imported as a surveyor would (``add-epoch``, ``add-setup``); planned together when the settings say
        ``plan_together true``.
        """
        out: list[list] = []
        for folder, path in zip(folders, coarse, strict=True):
            self._import(Path(folder), Path(path))
        label = self.labels[Path(folders[0])]
        with Campaign.open(self.dir) as c:
            for folder in folders:
                k = _setup_number(Path(folder))
                try:
                    plan: ScanPlan = plan_epoch(c, label, setup=k)
                except SurveyError as exc:  # that set-up gets no fine scans; the others keep theirs
                    self.refused[label if k == 1 else f"{label} set-up {k}"] = str(exc).splitlines()[0]
                    out.append([])
                    continue
                out.append(list(plan.rois))
        return out


def _setup_number(folder: Path) -> int:
    """The set-up a simulated visit folder holds (``setup2`` -> 2; a visit of one set-up -> 1)."""
    name = folder.name
    return int(name[5:]) if name.startswith("setup") and name[5:].isdigit() else 1


def run_study(root: Path, model: BridgeModel, visits: Sequence[EpochConditions], *, seed: int = 0,
              stations: Sequence[Sequence[ScannerSetup]] | None = None, coarse_step_deg: float = 0.05,
              settings: dict | None = None, compare_without: bool = False,
              coarse_first: bool = False, air_temperatures_c: Sequence[float] | None = None) -> dict[str, StudyScore]:
    """Simulate, plan, import and process a campaign; score it (and, optionally, the same without corrections).

    ``coarse_first``: every set-up's coarse scan of a visit is taken and imported before any is planned, so that
    the product can plan them together (``plan_together`` true in ``settings``; false: each alone, but from the
    same scans). Default: each set-up planned and fine-scanned before the next one's coarse scan, as before.
    ``air_temperatures_c``: the air's temperature at each visit (degC), logged hourly around it and imported as the
    campaign's air-temperature series before processing, as the demo does (the visits' range scales are the
    caller's: e.g. :func:`lidar.systematic.atmosphere.range_scale_ppm` of these temperatures).

    Returns ``{"corrected": score}`` (and ``"uncorrected"``: the same scans with ``field_model false``).
    """
    root = Path(root)
    field_dir, camp = root / "field", root / "campaign"
    for p in (field_dir, camp):
        shutil.rmtree(p, ignore_errors=True)
    planner = ProductPlanner(camp, field_dir / "layout.csv", span_m=model.span_m, settings=settings)
    write_campaign(field_dir, model, visits, plan_for=planner, stations=stations, seed=seed,
                   coarse_step_deg=coarse_step_deg, plan_visit=planner.plan_visit if coarse_first else None)
    with Campaign.open(camp) as c:
        planner.import_fine(c, list(planner.labels))  # the rest (the last set-up of each visit)
        if air_temperatures_c is not None:
            _import_air(c, root / "temperature.csv", air_temperatures_c)
        process(c)
    out = {"corrected": score_campaign(camp, field_dir, planner.labels)}
    out["corrected"].refused = dict(planner.refused)
    if compare_without:
        other = root / "campaign-uncorrected"
        shutil.rmtree(other, ignore_errors=True)
        shutil.copytree(camp, other, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
        with Campaign.open(other) as c:
            set_parameter(c, "field_model", "false")
            process(c)
        out["uncorrected"] = score_campaign(other, field_dir, planner.labels)
    return out


def _import_air(c: Campaign, path: Path, temperatures_c: Sequence[float]) -> None:
    """The air temperature of visit k (its date START + k weeks), read hourly from 2 h before to 2 h after it."""
    lines = ["time,temperature_degC"]
    for k, temp in enumerate(temperatures_c):
        for h in range(-2, 3):
            when = START + dt.timedelta(days=7 * k, hours=h)
            lines.append(f"{when.strftime('%Y-%m-%dT%H:%M')}Z,{float(temp):.2f}")
    path.write_text("\n".join(lines) + "\n")
    import_env(c, path, kind="temperature", name="air-temperature")


def _truth(folder: Path) -> ScanTruth:
    return ScanTruth.load(folder / "truth.json")


def score_campaign(camp: Path, field_dir: Path, labels: dict) -> StudyScore:
    """Every displacement, along-span movement and scale of a processed study campaign against the truth.

    ``labels`` maps each simulated visit (or set-up) folder to its epoch; the truth of a visit is its first
    set-up's (the bridge is in one state for all of them).
    """
    by_label: dict[str, ScanTruth] = {}
    for folder, lab in sorted(labels.items(), key=lambda kv: _setup_number(kv[0])):
        if lab not in by_label and (folder / "truth.json").exists():
            by_label[lab] = _truth(folder)
    sc = StudyScore()
    with Campaign.open(camp, writable=False) as c:
        base = c.settings().get("baseline")
        if base not in by_label:
            return sc
        tb = by_label[base]
        lay = c.layout()
        deck = {t for t, g in zip(lay.ids, lay.groups, strict=False) if g == "measurement"}
        later = [e.label for e in c.epochs() if e.label != base and e.label in by_label]
        number = {e.label: k + 1 for k, e in enumerate(c.epochs())}
        sc.expected = len(deck) * len(later)  # every deck target of the layout in every later visit
        sc.missing = sc.expected
        for r in c.displacements():
            if r.epoch == base or r.epoch not in by_label:
                continue
            t = by_label[r.epoch]
            if r.displacement_m is None or r.sigma_m is None or not math.isfinite(r.displacement_m):
                continue
            sc.missing -= r.reflector in deck
            true = t.target(r.reflector).vertical_displacement_m - tb.target(r.reflector).vertical_displacement_m
            sc.errors_mm.append((r.displacement_m - true) * 1e3)
            sc.sigmas_mm.append(r.sigma_m * 1e3)
            sc.warned.append(any(severity(f) in (WARNING, PROBLEM) for f in r.flags))
            sc.visit_numbers.append(number.get(r.epoch, 0))
            along_t = getattr(t.target(r.reflector), "along_span_m", None)
            if r.along_m is not None and along_t is not None:
                sc.along_errors_mm.append((r.along_m - (along_t - tb.target(r.reflector).along_span_m)) * 1e3)
                sc.along_sigmas_mm.append((r.along_sigma_m or 0.0) * 1e3)
                sc.along_warned.append(sc.warned[-1])
        for e in c.epochs():
            if e.label == base or e.label not in by_label:
                continue
            ds = c.displacement_set(e.label)
            sysm = c.systematics(e.label)
            if "scale_ppm" in sysm and sysm.get("scale_determined", True):
                # the scale during each visit's scans of targets (what one scale a visit measures), not at its start
                truth_ppm = by_label[e.label].range_scale_during_ppm() - tb.range_scale_during_ppm()
                sc.scale_errors_ppm.append(float(sysm["scale_ppm"]) - truth_ppm)
                sc.scale_sigmas_ppm.append(float(sysm.get("scale_sigma_ppm", float("nan"))))
            if ds is not None:
                sc.reference_flags += [(e.label, f) for f in ds.flags if code(f).startswith("reference_")]
                sc.scale_flags += [(e.label, f) for f in ds.flags
                                   if code(f) in (FLAG_ATMOSPHERE_DISAGREES, FLAG_PIER_MOVED)]
    return sc


def print_table(rows: dict[str, dict[str, StudyScore]]) -> str:
    """The scores as a Markdown table (one line per scenario and correction)."""
    head = "| scenario | corrections | RMS mm | max mm | within 2σ | beyond 3σ silent | along: within 2σ | " \
           "along: beyond 3σ silent | scale max ppm | scale within 2σ | reference flags | measured |"
    lines = [head, "|" + "---|" * 12]
    for name, scores in rows.items():
        for kind, s in scores.items():
            r = s.row()
            lines.append(f"| {name} | {kind} | {r['rms_mm']:.3f} | {r['max_mm']:.3f} | {r['within_2sigma']:.0%} | "
                         f"{r['silent_beyond_3sigma']:.1%} | {r['along_within_2sigma']:.0%} | "
                         f"{r['along_silent_beyond_3sigma']:.1%} | {r['scale_max_ppm']:.1f} | "
                         f"{r['scale_within_2sigma']:.0%} | {r['reference_flags']} | {r['measured']} |")
    return "\n".join(lines)


def save_scores(path: Path, rows: dict[str, dict[str, StudyScore]]) -> Path:
    """The scores as JSON."""
    path.write_text(json.dumps({n: {k: s.row() for k, s in v.items()} for n, v in rows.items()}, indent=1))
    return path

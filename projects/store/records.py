"""Typed records of what a campaign stores.

:class:`projects.store.Campaign` hands these out instead of database rows, so a caller reads
``epoch.label`` rather than ``row["label"]`` and never decodes JSON columns itself. Records are frozen:
changing a campaign goes through the store's methods, never through a record.

Dates are ISO 8601 text in UTC as stored (``datetime``); :attr:`Epoch.when` gives the parsed value.
Lengths are metres unless the name says otherwise.
"""
from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from projects.store.setup_tables import frames_from_json


def now_iso() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat()


class _Plain:
    """Records that export themselves as plain values (tables, JSON)."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)  # type: ignore[call-overload]


@dataclass(frozen=True)
class Reflector:
    """A retro-reflective target of the layout.

    Attributes
    ----------
    id, group
        Its name and ``"reference"`` (on a pier) or ``"measurement"`` (on the deck).
    xyz_layout : tuple of 3 float
        Position in the layout frame, metres.
    diameter_m : float
        Disc diameter, metres.
    normal_layout : tuple of 3 float
        Unit normal in the layout frame; NaNs when the layout gives none.
    installed, retired : str or None
        ISO date-times from which it is expected in scans, and after which it no longer is.
    replaces : str or None
        The target it took over from (its history continues this one's).
    note : str
    """

    id: str
    group: str
    xyz_layout: tuple[float, float, float]
    diameter_m: float
    normal_layout: tuple[float, float, float] = (float("nan"),) * 3
    installed: str | None = None
    retired: str | None = None
    replaces: str | None = None
    note: str = ""

    @property
    def is_reference(self) -> bool:
        return self.group == "reference"

    def expected_at(self, at: str | None) -> bool:
        """Whether the target is in place at the ISO date-time ``at`` (None: now, i.e. not retired)."""
        if at is None:
            return not self.retired
        return not ((self.installed and self.installed > at) or (self.retired and self.retired <= at))

    def to_dict(self) -> dict[str, Any]:
        """Plain values for tables and exports (``x``, ``y``, ``z``, ``nx``... as columns)."""
        return {"id": self.id, "group": self.group, "x": self.xyz_layout[0], "y": self.xyz_layout[1],
                "z": self.xyz_layout[2], "diameter_m": self.diameter_m, "nx": self.normal_layout[0],
                "ny": self.normal_layout[1], "nz": self.normal_layout[2], "installed": self.installed,
                "retired": self.retired, "replaces": self.replaces, "note": self.note}


@dataclass(frozen=True)
class Epoch(_Plain):
    """One weekly visit: its label, date-time (ISO 8601, UTC), notes and when it was recorded."""

    label: str
    datetime: str
    notes: str = ""
    created: str = ""

    @property
    def when(self) -> dt.datetime:
        """The visit's date-time, timezone-aware."""
        return dt.datetime.fromisoformat(self.datetime)

    @property
    def date(self) -> str:
        """The visit's date, ``YYYY-MM-DD``."""
        return self.datetime[:10]


@dataclass(frozen=True)
class ScanFile(_Plain):
    """A scan file imported into an epoch.

    ``role`` is ``"coarse"`` or ``"fine"``; ``stored_path`` is
    relative to the campaign folder; ``size`` in bytes. ``setup`` is the set-up it belongs to (the first,
    for a file holding several scan positions), ``frame`` the JSON of :attr:`frames` (None: one set-up,
    points in the scanner frame as stored).
    """

    sha256: str
    epoch: str
    role: str
    stored_path: str
    original_path: str
    size: int
    imported: str
    setup: int = 1
    frame: str | None = None

    @property
    def frames(self) -> dict:
        """Set-up number -> :class:`lidar.io.poses.FileFrame`: how the file's points reach each set-up's frame."""
        return frames_from_json(self.frame)

    @property
    def setups(self) -> tuple[int, ...]:
        """The set-ups the file holds scans of."""
        return tuple(sorted(self.frames)) or (self.setup,)

    def frame_for(self, setup: int):
        """The :class:`lidar.io.poses.FileFrame` of one set-up (None: read the file as it is)."""
        return self.frames.get(setup)


@dataclass(frozen=True)
class EpochResult:
    """How far processing has taken an epoch.

    ``stage`` is ``"planned"`` or ``"measured"``, with the
    hash of the inputs it was computed from.
    """

    epoch: str
    stage: str
    inputs_hash: str
    processed: str


@dataclass(frozen=True)
class StoredPlan:
    """An epoch's stored scan plan with the hash of the inputs it was made from.

    ``plan`` is a :class:`lidar.plan.ScanPlan`; ``plan_json`` its contract JSON as stored.
    """

    epoch: str
    plan: Any
    plan_json: dict
    inputs_hash: str
    created: str

    @property
    def edited(self) -> bool:
        """Whether the windows were edited by hand (see :func:`projects.processing.save_edited_plan`)."""
        return bool(self.plan_json.get("edited"))

    @property
    def identification(self) -> dict:
        """What the coarse scan's identification recorded with the plan (detections, fit RMS, missing)."""
        return dict(self.plan_json.get("identification") or {})


@dataclass(frozen=True)
class DisplacementSet:
    """What an epoch's displacements were computed with.

    Attributes
    ----------
    normal_socs : ndarray, shape (3,)
        The deck normal the displacements are measured along, scanner frame.
    reference_point_socs : ndarray, shape (3,)
    reference_ids : tuple of str
        Pier targets the frame motion was fitted to.
    normal_mode : str
    flags : tuple of str
        The epoch's own flags (see :mod:`common.flags`).
    """

    epoch: str
    baseline: str
    inputs_hash: str
    normal_socs: np.ndarray
    reference_point_socs: np.ndarray
    reference_ids: tuple[str, ...]
    normal_mode: str
    flags: tuple[str, ...]
    processed: str


@dataclass(frozen=True)
class DisplacementRecord:
    """One target's stored displacement in one epoch, with its own flags and its epoch's.

    Metres, positive up; None where none could be computed.
    """

    epoch: str
    datetime: str
    reflector: str
    displacement_m: float | None
    sigma_m: float | None
    flags: tuple[str, ...]
    epoch_flags: tuple[str, ...]
    baseline: str
    extra: Mapping[str, Any] = field(default_factory=dict)  # along_m, along_sigma_m, budget (metres)
    systematics: Mapping[str, Any] = field(default_factory=dict)  # the epoch's scale_ppm, drift...

    @property
    def when(self) -> dt.datetime:
        return dt.datetime.fromisoformat(self.datetime)

    @property
    def along_m(self) -> float | None:
        """Movement along the bridge axis (positive away from the first pier), metres; None without one."""
        return self.extra.get("along_m")

    @property
    def along_sigma_m(self) -> float | None:
        return self.extra.get("along_sigma_m")

    @property
    def budget(self) -> Mapping[str, float | None]:
        """The terms of ``sigma_m`` (metres): noise, frame, scale, bias, drift (absent when not stored)."""
        return self.extra.get("budget") or {}


@dataclass(frozen=True)
class ReferenceCheck:
    """How a pier target moved between the baseline and an epoch (metres)."""

    epoch: str
    reflector: str
    median_change_m: float | None
    max_change_m: float | None
    moved: bool
    missing: bool
    suspect: bool


@dataclass(frozen=True)
class LimitRecord:
    """A limit in force.

    ``reflector`` is a target id or ``"*"`` for every measurement target;
    ``limit`` a :class:`projects.limits.Limit`.
    """

    reflector: str
    limit: Any


@dataclass(frozen=True)
class LogEntry(_Plain):
    """One line of the campaign's log: what was done, to which epoch, with its details."""

    id: int
    time: str
    action: str
    epoch: str | None
    details: dict = field(default_factory=dict)


@dataclass(frozen=True)
class CheckVerdict(_Plain):
    """What the on-site check last said of an epoch's fine scans, while it still holds.

    Attributes
    ----------
    epoch : str
    time : str
        When the (latest) check was made.
    rescan : tuple of str
        The targets it asked to re-scan (empty: every target was good).
    reasons : dict
        ``target -> why`` ("211 of 1036 planned points", "not found"...).
    drifted : bool
        Whether the closure showed the set-up turned beyond the instrument's tolerance (a re-scan too).
    accepted : bool
        Whether the user chose to process the epoch as it is (``process --accept-check``, or the application's
        question answered yes).
    """

    epoch: str
    time: str
    rescan: tuple[str, ...] = ()
    reasons: dict = field(default_factory=dict)
    drifted: bool = False
    accepted: bool = False

    @property
    def asks_rescan(self) -> bool:
        """Whether the check asked for a re-scan that was neither made nor accepted."""
        return (bool(self.rescan) or self.drifted) and not self.accepted

    def line(self) -> str:
        """The verdict in one line: 're-scan M3 (211 of 1036 planned points)'."""
        if not self.rescan and not self.drifted:
            return "every target good"
        what = [f"{t} ({self.reasons[t]})" if self.reasons.get(t) else t for t in self.rescan]
        if self.drifted:
            what.append("the set-up (it turned beyond the instrument's tolerance)")
        return "re-scan " + ", ".join(what)


@dataclass(frozen=True)
class SeriesRecord(_Plain):
    """An imported time series (a camera's displacements or an environment quantity), without its arrays.

    ``reflector`` is the LiDAR target a camera series watches (None for environment series); ``kind``
    the environment quantity (``"camera"`` for camera series). ``options`` say how the file was read
    (column, unit, time zone, sign) and ``summary`` what it held (rows, period, sampling, gaps, bad rows).
    """

    name: str
    kind: str
    reflector: str | None
    sha256: str
    stored_path: str
    original_path: str
    imported: str
    options: dict
    summary: dict


@dataclass(frozen=True)
class EventRecord(_Plain):
    """Something that explains a change: a construction step, a load, a repair (``date`` ISO 8601 UTC)."""

    id: int
    date: str
    kind: str
    label: str
    load_kn_m: float | None = None

    @property
    def when(self) -> dt.datetime:
        return dt.datetime.fromisoformat(self.date)


@dataclass(frozen=True)
class PredictionRecord:
    """A target's stored design prediction.

    How it was aligned (``options``) and its curve as stored
    (``arrays``: the npz bytes of time_ns and value_mm, unaligned).
    """

    reflector: str
    options: dict
    arrays: bytes
    sha256: str = ""
    stored_path: str = ""
    original_path: str = ""


@dataclass(frozen=True)
class CrossvalRecord:
    """A camera series' stored cross-validation with LiDAR.

    ``summary`` is the JSON document of :class:`vision.crossval.CrossValidation`.
    """

    series: str
    summary: dict
    created: str


@dataclass(frozen=True)
class ComparisonRecord:
    """A stored whole-scan comparison of two epochs; ``summary`` as :mod:`projects.compare.whole_scan` writes it."""

    from_epoch: str
    to_epoch: str
    method: str
    summary: dict
    created: str


@dataclass(frozen=True, eq=False)
class EpochInputs:
    """Everything the store knows about one epoch that processing needs, read at one moment.

    Attributes
    ----------
    epoch : Epoch
    coarse, fine : tuple of ScanFile
        The set-up's scan files by role, in import order.
    plan : StoredPlan or None
        Its stored plan (None when it has none, or when it was not asked for).
    result : EpochResult or None
        How far processing has taken it.
    layout : lidar.layout.Layout
        The reflectors expected at its date.
    profile : lidar.scanner_profile.ScannerProfile
        Its scanner: its own when it has one, else the campaign's.
    settings : dict
        The campaign's settings (processing parameters among them).
    setup : int
        Which set-up of the visit these are (1-based).
    setups : tuple of int
        Every set-up the visit has.
    preview_to_remake : bool
        Its stored map preview is damaged and planning again would remake it (read with the plan only:
        :meth:`projects.store.campaign.Campaign.preview_to_remake`).
    """

    epoch: Epoch
    coarse: tuple[ScanFile, ...]
    fine: tuple[ScanFile, ...]
    plan: StoredPlan | None
    result: EpochResult | None
    layout: Any
    profile: Any
    settings: dict
    setup: int = 1
    setups: tuple[int, ...] = (1,)
    preview_to_remake: bool = False

    @property
    def label(self) -> str:
        return self.epoch.label

"""Ground-truth records of simulated scans (what the processing must recover).

Format history: version 1 held the pose, the midspan displacement and per target its position, normal,
vertical displacement and visibility; version 2 adds per target the along-span movement, the incidence, the
range, the range bias applied, the time scanned and the centre as the instrument reported it, and per visit
the spans, the span displacements, the deck strain, the atmosphere's scale, the range walk, the clipping, the
drift and every scan's time span. Version-1 files load with those at their "off" values. The instrument's axis
errors (``axis_errors``) were added within version 2; files without them load with none.
"""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

TRUTH_FORMAT_VERSION = 2


@dataclass(frozen=True)
class TargetTruth:
    """A simulated target as it really was in one scan.

    Attributes
    ----------
    id, group : str
    centre_bridge_m : (3,) float tuple
        Deformed centre, bridge frame, metres.
    centre_socs_m : (3,) float tuple
        The same in the set-up's scanner frame at the start of the visit (before any drift), metres.
    normal_socs : (3,) float tuple
    vertical_displacement_m : float
        Up positive, metres (deflection plus any knock).
    moved, occluded, cable_tie : bool
    points_on_target : int or None
    along_span_m : float
        Movement along x (the deck's strain times the distance from the fixed bearing; 0 on piers), metres.
    cos_incidence : float or None
        |cos| of the incidence angle from the scanner at its centre.
    range_m : float or None
        True distance from the scanner origin to its centre, metres.
    range_bias_m : float
        Range walk at its centre (head-on strength of a full disc at this range and incidence), metres,
        positive = the range reads short.
    time_s : float or None
        Mean time of its points in this scan (seconds); None when untimed or not hit.
    centre_observed_socs_m : (3,) float tuple or None
        Where a noise-free instrument reports its centre: in the instrument's frame at ``time_s`` (drift), along
        the line of sight shortened by the bias and scaled by the atmosphere, metres.
    """

    id: str
    group: str
    centre_bridge_m: tuple[float, ...]
    centre_socs_m: tuple[float, ...]
    normal_socs: tuple[float, ...]
    vertical_displacement_m: float
    moved: bool = False
    occluded: bool = False
    cable_tie: bool = False
    points_on_target: int | None = None
    along_span_m: float = 0.0
    cos_incidence: float | None = None
    range_m: float | None = None
    range_bias_m: float = 0.0
    time_s: float | None = None
    centre_observed_socs_m: tuple[float, ...] | None = None


@dataclass(frozen=True)
class WindowTruth:
    """When one scan of a visit was made: its name (``coarse`` or the window's reflector), seconds."""

    name: str
    start_s: float
    end_s: float
    closure: bool = False


@dataclass(frozen=True)
class ScanTruth:
    """What a simulated scan (or visit) really held: the scanner's pose, every target's truth, the visit's effects.

    Attributes
    ----------
    scanner_pose : (4, 4) SOCS -> bridge frame at the start of the visit.
    midspan_displacement_m : float
    targets : tuple of TargetTruth
    removed : tuple of ids
    range_noise_m : float
    spans_m : tuple of float
        The bridge's spans (empty in version-1 files).
    span_displacements_m : tuple of float
        Midspan displacement of every span, metres, positive up.
    deck_strain : float
        Deck strain along x (dL / L).
    fixed_bearing_x_m : float
    range_scale_ppm : float
        Every range was multiplied by ``1 + ppm * 1e-6`` (at the visit's start when it changes during the visit).
    range_scale_rate_ppm_h : float
        How fast that scale changed during the visit (ppm an hour, from the start of ``timing``); 0: constant.
    range_walk : dict or None
        ``{"form": name, **parameters}`` of the range walk on retro-reflector returns.
    clipped_fraction : float
        Fraction of target points whose intensity was clipped at the ceiling.
    drift : dict or None
        :class:`~lidar.simulate.effects.DriftModel` parameters.
    timing : dict or None
        :class:`~lidar.simulate.effects.VisitTiming` parameters.
    windows : tuple of WindowTruth
        Time span of every scan, in the order scanned.
    axis_errors : dict or None
        :class:`~lidar.simulate.effects.AxisErrors` parameters (the instrument's axis and range zero errors).
    """

    scanner_pose: np.ndarray  # (4, 4) SOCS -> bridge frame
    midspan_displacement_m: float
    targets: tuple[TargetTruth, ...]
    removed: tuple[str, ...] = ()
    range_noise_m: float = 0.005
    spans_m: tuple[float, ...] = ()
    span_displacements_m: tuple[float, ...] = ()
    deck_strain: float = 0.0
    fixed_bearing_x_m: float = 0.0
    range_scale_ppm: float = 0.0
    range_walk: dict | None = None
    clipped_fraction: float = 0.0
    drift: dict | None = None
    timing: dict | None = None
    windows: tuple[WindowTruth, ...] = ()
    axis_errors: dict | None = None
    range_scale_rate_ppm_h: float = 0.0

    def target(self, target_id: str) -> TargetTruth:
        return next(t for t in self.targets if t.id == target_id)

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d.update(format_version=TRUTH_FORMAT_VERSION, scanner_pose=np.asarray(self.scanner_pose).tolist(),
                 removed=list(self.removed), targets=[asdict(t) for t in self.targets],
                 spans_m=list(self.spans_m), span_displacements_m=list(self.span_displacements_m),
                 windows=[asdict(w) for w in self.windows])
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ScanTruth:
        tuples = ("centre_bridge_m", "centre_socs_m", "normal_socs", "centre_observed_socs_m")
        known = {f.name for f in fields(TargetTruth)}
        def target(t: dict) -> TargetTruth:
            kw: dict = {k: (tuple(v) if k in tuples and v is not None else v) for k, v in t.items() if k in known}
            return TargetTruth(**kw)

        targets = tuple(target(t) for t in d["targets"])
        return cls(np.asarray(d["scanner_pose"]), float(d["midspan_displacement_m"]), targets,
                   tuple(d.get("removed", ())), float(d.get("range_noise_m", 0.005)),
                   spans_m=tuple(d.get("spans_m", ())),
                   span_displacements_m=tuple(d.get("span_displacements_m", ())),
                   deck_strain=float(d.get("deck_strain", 0.0)),
                   fixed_bearing_x_m=float(d.get("fixed_bearing_x_m", 0.0)),
                   range_scale_ppm=float(d.get("range_scale_ppm", 0.0)),
                   range_walk=d.get("range_walk"), clipped_fraction=float(d.get("clipped_fraction", 0.0)),
                   drift=d.get("drift"), timing=d.get("timing"),
                   windows=tuple(WindowTruth(**w) for w in d.get("windows", ())),
                   axis_errors=d.get("axis_errors"),
                   range_scale_rate_ppm_h=float(d.get("range_scale_rate_ppm_h", 0.0)))

    def range_scale_during_ppm(self) -> float:
        """The atmosphere's scale over the visit's scans of targets (ppm): what one scale fitted to the visit measures.

        A scale changing during the visit (``range_scale_rate_ppm_h``) is taken at the mean of the middles of the
        target windows (the coarse scan left out; the scale is linear in time, so this is its mean over them);
        ``range_scale_ppm`` when it does not change or no window was recorded.
        """
        mids = [0.5 * (w.start_s + w.end_s) for w in self.windows if w.name != "coarse"]
        if not self.range_scale_rate_ppm_h or not mids:
            return self.range_scale_ppm
        start = float((self.timing or {}).get("start_s", 0.0))
        return self.range_scale_ppm + self.range_scale_rate_ppm_h * (float(np.mean(mids)) - start) / 3600.0

    def save(self, path: str | os.PathLike) -> Path:
        p = Path(path)
        p.write_text(json.dumps(self.to_dict(), indent=1))
        return p

    @classmethod
    def load(cls, path: str | os.PathLike) -> ScanTruth:
        return cls.from_dict(json.loads(Path(path).read_text()))

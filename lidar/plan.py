"""Fine-scan planning: one angular window (ROI) per target, with steps that give it enough points.

The plan JSON is a contract shared with other tools::

    {"epoch": ..., "scanner_profile": ..., "total_seconds": ...,
     "rois": [{"reflector", "group", "phi_min_deg", "phi_max_deg", "theta_min_deg", "theta_max_deg",
               "phi_step_deg", "theta_step_deg", "range_m", "expected_points", "expected_seconds"}]}

``phi_min_deg < phi_max_deg`` always (a window across 0 deg starts below 0).
"""
from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from common.files import write_atomic
from lidar.angles import AngularWindow, direction_from_angles, spherical_from_xyz, window_around
from lidar.centroid import UNRESOLVED_RATIO, WEAK_RATIO, resolvability
from lidar.scanner_profile import VZ1000, ScannerProfile

if TYPE_CHECKING:  # a type only: the map's readers (lidar.io: pye57, laspy) are not a plan's start-up
    from lidar.reflectance_map import ReflectanceMap

PLAN_FORMAT_VERSION = 1
DEFAULT_INCIDENCE_COS = 0.6  # used when the surface around a target cannot be measured


@dataclass(frozen=True)
class PlanTarget:
    """What the planner needs to know of one target (scanner frame)."""

    id: str
    group: str
    xyz_socs: tuple[float, ...]
    diameter_m: float = 0.05
    predicted: bool = False
    incidence_cos: float | None = None
    normal_socs: tuple[float, ...] | None = None  # the layout's normal carried into the scanner frame, when known


@dataclass(frozen=True)
class RoiPlan:
    """The fine-scan window of one target and what it is expected to deliver."""

    reflector: str
    group: str
    window: AngularWindow
    range_m: float
    incidence_deg: float
    expected_points: int
    expected_target_points: int
    expected_seconds: float
    predicted: bool = False
    notes: tuple[str, ...] = ()
    closure: bool = False  # a window scanned again at the end of the visit (listed last); in JSON only when True

    def to_json(self) -> dict:
        w = self.window
        closure = {"closure": True} if self.closure else {}
        return {
            "reflector": self.reflector, "group": self.group,
            "phi_min_deg": float(w.phi_min_deg), "phi_max_deg": float(w.phi_max_deg),
            "theta_min_deg": float(w.theta_min_deg), "theta_max_deg": float(w.theta_max_deg),
            "phi_step_deg": w.phi_step_deg, "theta_step_deg": w.theta_step_deg,
            "range_m": round(self.range_m, 4), "expected_points": int(self.expected_points),
            "expected_seconds": round(self.expected_seconds, 2),
            "expected_target_points": int(self.expected_target_points),
            "incidence_deg": round(self.incidence_deg, 2), "predicted": self.predicted, "notes": list(self.notes),
            **closure,
        }

    @classmethod
    def from_json(cls, d: dict) -> RoiPlan:
        try:
            w = AngularWindow(float(d["phi_min_deg"]), float(d["phi_max_deg"]), float(d["theta_min_deg"]),
                              float(d["theta_max_deg"]), float(d["phi_step_deg"]), float(d["theta_step_deg"]))
            return cls(str(d["reflector"]), str(d.get("group", "")), w, float(d["range_m"]),
                       float(d.get("incidence_deg", float("nan"))), int(d.get("expected_points", 0)),
                       int(d.get("expected_target_points", 0)), float(d.get("expected_seconds", 0.0)),
                       bool(d.get("predicted", False)), tuple(d.get("notes", ())), bool(d.get("closure", False)))
        except KeyError as exc:
            raise InputError(f"plan ROI is missing the field {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"plan ROI has a malformed value ({exc})") from None


@dataclass(frozen=True)
class ScanPlan:
    """Fine-scan plan of one epoch."""

    epoch: str
    profile: ScannerProfile
    rois: tuple[RoiPlan, ...]
    min_points: int
    points_per_target: int
    budget_seconds: float
    warnings: tuple[str, ...] = ()
    dome_seconds: float = 0.0
    dome_step_deg: float | None = None
    skipped: tuple[tuple[str, str], ...] = ()  # (reflector, why): targets this station cannot measure

    @property
    def total_seconds(self) -> float:
        """Windows plus, for a full-dome-only instrument, its one dome scan, seconds."""
        return float(sum(r.expected_seconds for r in self.rois)) + self.dome_seconds

    def instrument_window(self, roi: RoiPlan) -> dict:
        """A window in the instrument's own angles and resolution setting (see :class:`ScannerProfile`)."""
        w = roi.window
        p = self.profile
        h0, v0 = p.instrument_angles(w.theta_min_deg, w.phi_min_deg)
        h1, v1 = p.instrument_angles(w.theta_max_deg, w.phi_max_deg)
        hs, he = (float(h0), float(h1)) if p.horizontal_direction == "ccw" else (float(h1), float(h0))
        vs, ve = sorted((float(v0), float(v1)))
        if p.step_presets:
            res = p.preset_label(w.theta_step_deg) + (f", quality {p.quality}" if p.quality else "")
        else:
            res = f"vertical {w.theta_step_deg:.4f} deg, horizontal {w.phi_step_deg:.4f} deg"
        return {"h_start_deg": round(hs, 4), "h_end_deg": round(he, 4), "v_start_deg": round(vs, 4),
                "v_end_deg": round(ve, 4), "vertical": p.vertical_reference, "resolution": res}

    def roi(self, reflector: str) -> RoiPlan:
        for r in self.rois:
            if r.reflector == reflector:
                return r
        raise InputError(f"the plan has no window for reflector {reflector!r}")

    def to_json(self) -> dict:
        return {
            "format_version": PLAN_FORMAT_VERSION, "epoch": self.epoch, "scanner_profile": self.profile.name,
            "scanner": self.profile.to_dict(), "total_seconds": round(self.total_seconds, 2),
            "budget_seconds": self.budget_seconds, "min_points": self.min_points,
            "points_per_target": self.points_per_target, "warnings": list(self.warnings),
            "windowed": self.profile.windowed, "dome_seconds": round(self.dome_seconds, 2),
            "dome_step_deg": self.dome_step_deg, "angle_convention": self.profile.angle_convention(),
            "rois": [dict(r.to_json(), instrument=self.instrument_window(r)) for r in self.rois],
            **({"skipped": [{"reflector": k, "reason": why} for k, why in self.skipped]} if self.skipped else {}),
        }

    @classmethod
    def from_json(cls, d: dict, *, source: str = "plan") -> ScanPlan:
        if not isinstance(d, dict) or "rois" not in d:
            raise InputError(f"{source}: not a BridgeSurvey plan (no 'rois' list)")
        version = int(d.get("format_version", 1))
        if version > PLAN_FORMAT_VERSION:
            raise InputError(f"{source}: plan format {version} is newer than this BridgeSurvey understands "
                             f"({PLAN_FORMAT_VERSION}); update BridgeSurvey")
        profile = ScannerProfile.from_dict(d["scanner"], source=f"{source}: scanner") \
            if isinstance(d.get("scanner"), dict) else VZ1000
        try:
            rois = tuple(RoiPlan.from_json(r) for r in d["rois"])
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None
        dome_step = d.get("dome_step_deg")
        return cls(str(d.get("epoch", "")), profile, rois, int(d.get("min_points", 1000)),
                   int(d.get("points_per_target", d.get("min_points", 1000))),
                   float(d.get("budget_seconds", 3600.0)), tuple(d.get("warnings", ())),
                   float(d.get("dome_seconds", 0.0) or 0.0), None if dome_step is None else float(dome_step),
                   tuple((str(x["reflector"]), str(x["reason"])) for x in d.get("skipped", ())))

    def save(self, path: str | os.PathLike) -> Path:

        return write_atomic(path, json.dumps(self.to_json(), indent=2))

    @classmethod
    def load(cls, path: str | os.PathLike) -> ScanPlan:
        p = Path(path)
        try:
            d = json.loads(p.read_text())
        except FileNotFoundError:
            raise InputError(f"{p}: plan file not found") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"{p}: not a JSON plan ({exc})") from None
        return cls.from_json(d, source=str(p))


def incidence_from_map(rmap: ReflectanceMap, xyz_socs: ArrayLike, *, radius_m: float = 0.35) -> float | None:
    """|cos| of the incidence angle at a target, from a plane fitted to the map's cells around it."""
    xyz = np.asarray(xyz_socs, dtype=np.float64)
    theta, phi, rng = spherical_from_xyz(xyz[None])
    row, col = rmap.cells_of(theta, phi)
    half = max(2, int(np.degrees(radius_m / rng[0]) / rmap.step_deg) + 1)
    r0, c0 = int(round(row[0])), int(round(col[0]))
    h, w = rmap.shape
    rows = np.arange(max(0, r0 - half), min(h, r0 + half + 1))
    cols = np.arange(max(0, c0 - 2 * half), min(w, c0 + 2 * half + 1))
    if rows.size == 0 or cols.size == 0:
        return None
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    ranges = rmap.range_m[rr, cc]
    ok = np.isfinite(ranges)
    if np.count_nonzero(ok) < 8:
        return None
    t, p = rmap.cell_angles(rr[ok], cc[ok])
    pts = rmap.xyz_of(t, p, ranges[ok])
    near = np.linalg.norm(pts - xyz, axis=1) <= radius_m
    if np.count_nonzero(near) < 8:
        return None
    pts = pts[near]
    _, _, vt = np.linalg.svd(pts - pts.mean(axis=0), full_matrices=False)
    normal = vt[2]
    view = xyz / np.linalg.norm(xyz)
    return float(abs(normal @ view))


def choose_steps(omega_sr: float, sin_theta: float, n_points: float, profile: ScannerProfile) -> tuple[float, float]:
    """(theta_step, phi_step) in degrees giving ``n_points`` on a target of solid angle ``omega_sr``.

    Sampling is made spatially even (``theta_step == phi_step * sin(theta)``)
    within the instrument's finest steps; steps are rounded down to 0.0001 deg.
    An instrument that offers only resolution presets gets the coarsest preset
    that still gives ``n_points`` (the finest when none does), the same step in
    both angles as its panel sets it.
    """
    cell = omega_sr / max(n_points, 1.0)  # rad^2 per point: dtheta * dphi * sin(theta)
    s = max(sin_theta, 1e-3)
    if profile.step_presets:
        step = profile.preset_for(math.degrees(math.sqrt(cell / s)))[1]
        return step, step
    min_t = math.radians(profile.min_theta_step_deg)
    min_p = math.radians(profile.min_phi_step_deg)
    dt = math.sqrt(cell)
    dp = dt / s
    if dp < min_p:
        dp = min_p
        dt = cell / (dp * s)
    if dt < min_t:
        dt = min_t
        dp = max(min_p, cell / (dt * s))
    def down(v_rad, floor_deg):
        return max(floor_deg, math.floor(math.degrees(v_rad) * 1e4) / 1e4)
    return down(dt, profile.min_theta_step_deg), down(dp, profile.min_phi_step_deg)


def plan_roi(target: PlanTarget, *, n_points: float, profile: ScannerProfile = VZ1000,
             margin_m: float = 0.10, step_deg: float | None = None) -> RoiPlan:
    """Window and steps for one target.

    ``step_deg`` imposes one step in both angles (a full-dome scan's preset); the window is then
    the part of that scan the target is measured from, and costs no time of its own.
    """
    xyz = np.asarray(target.xyz_socs, dtype=np.float64)
    theta_a, phi_a, rng = spherical_from_xyz(xyz[None])
    theta, phi, r = float(theta_a[0]), float(phi_a[0]), float(rng[0])
    if not (np.isfinite(r) and r > 0.1):
        raise InputError(f"reflector {target.id}: position {tuple(xyz)} is not a valid direction from the scanner")
    notes = []
    cos_inc = target.incidence_cos
    if cos_inc is None:
        cos_inc = DEFAULT_INCIDENCE_COS
        notes.append("incidence unknown: assumed 53 deg")
    cos_inc = float(np.clip(cos_inc, 0.05, 1.0))
    radius = target.diameter_m / 2
    omega = math.pi * radius ** 2 * cos_inc / r ** 2
    sin_t = math.sin(math.radians(theta))
    dt, dp = (step_deg, step_deg) if step_deg is not None else choose_steps(omega, sin_t, n_points, profile)
    margin = margin_m * (2.5 if target.predicted else 1.0)
    half_t = math.degrees(math.atan((radius + margin) / r))
    half_p = half_t / max(sin_t, 1e-3)
    window = window_around(theta, phi, half_t, half_p, dt, dp)
    lo, hi = profile.theta_fov_deg
    if window.theta_min_deg < lo or window.theta_max_deg > hi:
        notes.append("window reaches outside the scanner's vertical field of view")
    rows, cols = window.shape
    expected_target = omega / (math.radians(dt) * math.radians(dp) * sin_t)
    if expected_target < n_points * 0.999 and step_deg is None:
        notes.append(f"finest steps give only {int(expected_target)} points on the target")
    if step_deg is None:
        seconds = profile.window_seconds(window.phi_max_deg - window.phi_min_deg, dp, dt)
    else:
        seconds = 0.0
        notes.append("cut from the full-dome scan")
    if target.predicted:
        notes.append("position predicted from the layout (not resolved in the coarse scan)")
    return RoiPlan(target.id, target.group, window, r, math.degrees(math.acos(cos_inc)), rows * cols,
                   int(round(expected_target)), seconds, target.predicted, tuple(notes))


def plan_fine_scans(targets: Sequence[PlanTarget], *, epoch: str = "", profile: ScannerProfile = VZ1000,
                    closure: bool = False,
                    min_points: int = 1000, budget_seconds: float = 3600.0, margin_m: float = 0.10,
                    reference_factor: float = 1.0) -> ScanPlan:
    """Plan the fine scans of an epoch.

    Parameters
    ----------
    targets : sequence of PlanTarget
        Every target to scan, in the scanner frame.
    epoch : str, keyword-only
    profile : ScannerProfile, keyword-only
        Default: Riegl VZ-1000.
    min_points : int, keyword-only
        Points each target should receive. Default 1000.
    budget_seconds : float, keyword-only
        Time available for the fine scans. Default 3600 s (60 min). When the
        plan would take longer, the points per target are reduced evenly until
        it fits, and the plan says so in its warnings.
    margin_m : float, keyword-only
        Background around each target inside its window (each side), metres;
        2.5x for predicted targets. Default 0.10 m.
    closure : bool, keyword-only
        End the plan with a closure window: the first reference target's window again, so that the
        set-up's drift during the visit can be measured (:mod:`lidar.systematic`). Default False.
    reference_factor : float, keyword-only
        The reference targets' windows are planned for this many times the points of the others (as many as the
        instrument's finest steps give, and cut with the others when over the budget). Every displacement of a
        visit is referred to them, so their centroids' noise is in every value. Default 1 (the product's
        ``reference_points_factor``).

    Returns
    -------
    ScanPlan
    """
    if min_points < 10:
        raise InputError(f"min_points must be at least 10, got {min_points}")
    if not (math.isfinite(reference_factor) and reference_factor >= 1.0):
        raise InputError(f"the reference targets' factor of points must be a number >= 1, got {reference_factor}")
    if not budget_seconds > 0:
        raise InputError("the time budget must be positive")
    if not targets:
        raise InputError("nothing to plan: no targets")
    targets, weak, skipped = _measurable(targets, profile)
    if not targets and not weak:
        raise InputError("nothing to plan: no target can be measured from this station ("
                         + "; ".join(f"{k} {why}" for k, why in skipped) + ")")
    if not profile.windowed:  # a dome scans the weak targets too, at no extra time
        dome = _plan_full_dome(targets + [t for t, _ in weak], epoch=epoch, profile=profile, min_points=min_points,
                               budget_seconds=budget_seconds, margin_m=margin_m)
        return replace(dome, skipped=tuple(skipped)) if skipped else dome
    only_weak = {t.id: why for t, why in weak} if not targets else {}
    if only_weak:  # only weak ones: they are the plan
        targets, weak = [t for t, _ in weak], []
    n = float(min_points)
    warnings: list[str] = []

    def windows(points: float, factor: float) -> tuple[list[RoiPlan], float]:
        out = [plan_roi(t, n_points=points * (factor if t.group == "reference" else 1.0), profile=profile,
                        margin_m=margin_m) for t in targets]
        return out, sum(r.expected_seconds for r in out)

    factor = _reference_factor(windows, n, reference_factor, budget_seconds)
    for _ in range(30):
        rois, total = windows(n, factor)
        if total <= budget_seconds * 1.0001:
            break
        overhead = profile.window_overhead_s * len(rois)
        if overhead >= budget_seconds:
            warnings.append(f"the budget of {budget_seconds:.0f} s does not even cover moving between "
                            f"{len(rois)} windows")
            break
        factor = (budget_seconds - overhead) / max(total - overhead, 1e-9)
        new_n = max(50.0, n * factor * 0.98)
        if new_n >= n - 0.5:
            break
        n = new_n
    if n < min_points:
        warnings.append(f"over the time budget with {min_points} points per target: reduced to about "
                        f"{int(n)} points per target to fit {budget_seconds / 60:.0f} min")
    refs = [r.expected_seconds for r in rois if r.group == "reference"]
    reserve = refs[0] if closure and refs else 0.0  # the closure window's time is kept for it
    rois = [replace(r, notes=r.notes + (_weak_note(only_weak[r.reflector]),)) if r.reflector in only_weak else r
            for r in rois]
    rois, total, late = _weak_windows(rois, weak, n_points=n, total=total, budget_seconds=budget_seconds - reserve,
                                      profile=profile, margin_m=margin_m)
    skipped.extend(late)
    if closure:
        rois = _interleave_references(rois)
        first = next((r for r in rois if r.group == "reference"), None)
        if first is not None:
            rois.append(replace(first, closure=True, notes=first.notes + (
                "closure: the first reference target again, at the end, for the set-up's drift",)))
            total += first.expected_seconds
    if total > budget_seconds * 1.0001:
        warnings.append(f"the plan takes {total / 60:.1f} min, over the budget of {budget_seconds / 60:.0f} min")
    if skipped:
        narrow = [k for k, why in skipped if "no time is left" not in why]
        if narrow:
            warnings.append("not planned (narrower than the beam from here, measure from another station): "
                            + ", ".join(narrow))
        if len(narrow) < len(skipped):
            warnings.append("not planned (weak from here and no time left in the budget): "
                            + ", ".join(k for k, why in skipped if k not in narrow))
    return ScanPlan(epoch, profile, tuple(rois), int(min_points), int(n), float(budget_seconds), tuple(warnings),
                    skipped=tuple(skipped))


def _measurable(targets: Sequence[PlanTarget], profile: ScannerProfile) -> tuple[list, list, list]:
    """The targets a fine scan measures well from this station, the weak ones, and why each other one cannot.

    A disc whose projected short axis is narrower than :data:`lidar.centroid.UNRESOLVED_RATIO` of the beam
    at its range returns only mixed pixels: its window would spend the visit's time on a centroid that
    would be refused. Below :data:`lidar.centroid.WEAK_RATIO` it is measured with a widened sigma: weak,
    planned only in the time left (:func:`_weak_windows`), most resolvable first.
    """
    keep, weak, skipped = [], [], []
    for t in targets:
        r = float(np.linalg.norm(t.xyz_socs))
        cos = t.incidence_cos if t.incidence_cos is not None else DEFAULT_INCIDENCE_COS
        q = resolvability(t.diameter_m, cos, r, profile)
        why = (f"at {r:.0f} m and {math.degrees(math.acos(min(max(cos, 0.0), 1.0))):.0f} deg "
               f"incidence the disc is {100 * q:.0f} % of the beam's width")
        if q < UNRESOLVED_RATIO:
            skipped.append((t.id, why))
        elif q < WEAK_RATIO:
            weak.append((q, t, why))
        else:
            keep.append(t)
    weak.sort(key=lambda e: -e[0])
    return keep, [(t, why) for _, t, why in weak], skipped


def coarse_step_needed_deg(diameter_m: float, cos_incidence: float, range_m: float) -> float:
    """The coarsest coarse-scan step (degrees) that puts two samples across a disc's short projected axis.

    A coarse scan finds a target from the samples on its disc; at grazing incidence the disc is
    ``D cos(incidence)`` wide: a 50 mm disc at 80 deg from 20 m spans 0.025 deg, so a 0.05 deg coarse scan
    misses it about half the time (its window then comes from the layout alone).
    """
    return math.degrees(diameter_m * max(float(cos_incidence), 0.0) / max(float(range_m), 1e-3)) / 2.0


def _weak_note(why: str) -> str:
    return f"weak: {why}; measured with a widened sigma and flagged grazing, planned in the time the budget leaves"


def _weak_windows(rois: list, weak: Sequence[tuple[PlanTarget, str]], *, n_points: float, total: float,
                  budget_seconds: float, profile: ScannerProfile, margin_m: float) -> tuple[list, float, list]:
    """The weak targets' windows that fit in the time the budget leaves, never shrinking another window.

    Returns the windows with the weak ones appended, the new total (s), and the weak targets left out
    with their reason.
    """
    out, late = list(rois), []
    for t, why in weak:
        roi = plan_roi(t, n_points=n_points, profile=profile, margin_m=margin_m)
        if total + roi.expected_seconds <= budget_seconds * 1.0001:
            out.append(replace(roi, notes=roi.notes + (_weak_note(why),)))
            total += roi.expected_seconds
        else:
            late.append((t.id, f"{why}: weak, and no time is left in the budget for it"))
    return out, total, late


def _reference_factor(windows: Callable[[float, float], tuple[list, float]], n: float, wanted: float,
                      budget_seconds: float) -> float:
    """The reference targets' factor of points that fits the budget.

    ``wanted`` if it fits; else the most that fits with every other target at ``n`` points (bisection); 1 when
    not even that does (the time goes to every target's points first).
    """
    if wanted <= 1.0 or windows(n, wanted)[1] <= budget_seconds * 1.0001:
        return wanted
    if windows(n, 1.0)[1] > budget_seconds * 1.0001:
        return 1.0
    lo, hi = 1.0, wanted
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if windows(n, mid)[1] <= budget_seconds * 1.0001 else (lo, mid)
    return lo


def _interleave_references(rois: list) -> list:
    """The windows in an order that spreads the reference targets over the visit.

    Each reference window opens a share of the deck windows: the reference targets are then seen at
    times spread over the whole visit, and with the closure at its end they fix the set-up's drift in
    all three axes (a deck target's window, whose target moves, says little about it).
    """
    refs = [r for r in rois if r.group == "reference"]
    others = [r for r in rois if r.group != "reference"]
    if not refs or not others:
        return list(rois)
    out: list = []
    chunks = np.array_split(np.arange(len(others)), len(refs))
    for ref, chunk in zip(refs, chunks, strict=False):
        out.append(ref)
        out.extend(others[i] for i in chunk)
    return out


def _plan_full_dome(targets: Sequence[PlanTarget], *, epoch: str, profile: ScannerProfile, min_points: int,
                    budget_seconds: float, margin_m: float) -> ScanPlan:
    """One full-dome scan at the coarsest preset giving every target ``min_points`` (within the budget)."""
    presets = profile.step_presets[::-1]  # coarse first (the profile keeps them finest first)

    def rois_at(step):
        return [plan_roi(t, n_points=min_points, profile=profile, margin_m=margin_m, step_deg=step) for t in targets]

    warnings = []
    label, step = presets[-1]
    for lab, st in presets:
        rois = rois_at(st)
        if min(r.expected_target_points for r in rois) >= min_points * 0.999:
            label, step = lab, st
            break
    else:  # none does: the finest, the last tried
        warnings.append(f"even the finest resolution ({label}) gives fewer than {min_points} points on some targets")
    dome = profile.full_dome_seconds(step)
    if dome > budget_seconds * 1.0001:
        fitting = [(lab, st) for lab, st in presets if profile.full_dome_seconds(st) <= budget_seconds]
        if fitting:
            lab2, st2 = fitting[-1]
            warnings.append(f"the full-dome scan at {label} takes {dome / 60:.1f} min, over the budget of "
                            f"{budget_seconds / 60:.0f} min: planned at {lab2} instead")
            label, step = lab2, st2
            rois = rois_at(step)
            dome = profile.full_dome_seconds(step)
        else:
            warnings.append(f"the plan takes {dome / 60:.1f} min, over the budget of {budget_seconds / 60:.0f} min")
    warnings.append(f"{profile.name} scans full domes only: one scan at {label}; every window is cut from it")
    points = min(r.expected_target_points for r in rois)
    return ScanPlan(epoch, profile, tuple(rois), int(min_points), int(min(points, min_points)), float(budget_seconds),
                    tuple(warnings), float(dome), float(step))


# ---------------------------------------------------------------------- editing a plan by hand
#: A window edited by hand keeps at least this margin around its target's disc, metres: the centroid needs the
#: disc's whole rim and a ring of background around it.
MIN_EDIT_MARGIN_M = 0.02


def target_extent(xyz_socs: ArrayLike, *, diameter_m: float, margin_m: float = MIN_EDIT_MARGIN_M) -> AngularWindow:
    """The smallest window holding a target's disc and a margin around it.

    Parameters
    ----------
    xyz_socs : (3,) array_like
        The target's centre in the scanner frame, metres.
    diameter_m : float, keyword-only
        The disc's diameter, metres.
    margin_m : float, keyword-only
        Kept around the disc, metres (default :data:`MIN_EDIT_MARGIN_M`).

    Returns
    -------
    AngularWindow
        Its steps are the extent's own size (the extent is a bound, not a scan).

    Examples
    --------
    >>> w = target_extent([0.0, 20.0, 0.0], diameter_m=0.05)  # 20 m away, level: 0.045 m each side
    >>> round(w.theta_max_deg - w.theta_min_deg, 4), round(w.phi_max_deg - w.phi_min_deg, 4)
    (0.2578, 0.2578)
    """
    theta_a, phi_a, rng = spherical_from_xyz(np.asarray(xyz_socs, dtype=np.float64).reshape(1, 3))
    theta, phi, r = float(theta_a[0]), float(phi_a[0]), float(rng[0])
    half_t = math.degrees(math.atan((diameter_m / 2.0 + margin_m) / max(r, 1e-3)))
    half_p = half_t / max(math.sin(math.radians(theta)), 1e-3)
    lo, hi = max(theta - half_t, 0.0), min(theta + half_t, 180.0)
    return AngularWindow(phi - half_p, phi + half_p, lo, hi, 2 * half_p, hi - lo)


def holds(window: AngularWindow, extent: AngularWindow) -> bool:
    """Whether ``window`` holds the whole of ``extent`` (azimuths compared across the 0/360 seam).

    >>> e = target_extent([0.0, 20.0, 0.0], diameter_m=0.05)
    >>> holds(AngularWindow(e.phi_min_deg - 0.1, e.phi_max_deg + 0.1, 89.0, 91.0, 0.01, 0.01), e)
    True
    >>> holds(AngularWindow(e.phi_min_deg + 0.05, e.phi_max_deg, 89.0, 91.0, 0.01, 0.01), e)
    False
    """
    tol = 1e-6  # degrees: windows are stored to 1e-6
    if extent.theta_min_deg < window.theta_min_deg - tol or extent.theta_max_deg > window.theta_max_deg + tol:
        return False
    shift = 360.0 * round(((window.phi_min_deg + window.phi_max_deg) - (extent.phi_min_deg + extent.phi_max_deg))
                          / 720.0)
    return (extent.phi_min_deg + shift >= window.phi_min_deg - tol
            and extent.phi_max_deg + shift <= window.phi_max_deg + tol)


EDITED_NOTE = "window edited by hand"


def edit_roi(roi: RoiPlan, *, phi_min_deg: float, phi_max_deg: float, theta_min_deg: float, theta_max_deg: float,
             profile: ScannerProfile = VZ1000) -> RoiPlan:
    """The same target's window moved or resized; its steps stay, points and seconds follow.

    The points expected on the target are unchanged while the target stays inside the window
    (the steps decide them); the window's points and seconds are recomputed.
    """
    w = roi.window
    window = AngularWindow(float(phi_min_deg), float(phi_max_deg), float(theta_min_deg), float(theta_max_deg),
                           w.phi_step_deg, w.theta_step_deg)
    rows, cols = window.shape
    seconds = profile.window_seconds(window.phi_max_deg - window.phi_min_deg, w.phi_step_deg, w.theta_step_deg) \
        if profile.windowed else 0.0
    notes = tuple(n for n in roi.notes if n != EDITED_NOTE) + (EDITED_NOTE,)
    return replace(roi, window=window, expected_points=rows * cols, expected_seconds=seconds, notes=notes)


def new_roi(reflector: str, group: str, *, phi_min_deg: float, phi_max_deg: float, theta_min_deg: float,
            theta_max_deg: float, range_m: float, diameter_m: float = 0.05, n_points: float = 1000,
            profile: ScannerProfile = VZ1000) -> RoiPlan:
    """A window drawn by hand around a target at ``range_m``: steps chosen for ``n_points`` on it."""
    theta = 0.5 * (theta_min_deg + theta_max_deg)
    phi = 0.5 * (phi_min_deg + phi_max_deg)
    xyz = direction_from_angles(np.array([theta]), np.array([phi]))[0] * float(range_m)
    base = plan_roi(PlanTarget(reflector, group, tuple(xyz), diameter_m), n_points=n_points, profile=profile)
    return edit_roi(base, phi_min_deg=phi_min_deg, phi_max_deg=phi_max_deg, theta_min_deg=theta_min_deg,
                    theta_max_deg=theta_max_deg, profile=profile)


def without_closure(plan: ScanPlan) -> ScanPlan:
    """The plan without its closure window (the drift of the visit is then measured on the references only)."""
    return replace(plan, rois=tuple(r for r in plan.rois if not r.closure))


def with_rois(plan: ScanPlan, rois: Sequence[RoiPlan]) -> ScanPlan:
    """The plan with another set of windows; the time budget is checked again.

    A closure window is not given: the plan's closure follows its target's (edited) window, at the end.
    """
    rois = [r for r in rois if not r.closure]
    ids = [r.reflector for r in rois]
    if len(set(ids)) != len(ids):
        raise InputError("a plan holds one window per reflector; two windows name the same reflector")
    closed = next((r.reflector for r in plan.rois if r.closure), None)
    target = next((r for r in rois if r.reflector == closed), None)
    if target is not None:
        rois.append(replace(target, closure=True, notes=next(r.notes for r in plan.rois if r.closure)))
    total = sum(r.expected_seconds for r in rois)
    warnings = [w for w in plan.warnings if "over the budget" not in w and not w.startswith("the plan takes")]
    if total > plan.budget_seconds * 1.0001:
        warnings.append(f"the plan takes {total / 60:.1f} min, over the budget of {plan.budget_seconds / 60:.0f} min")
    return replace(plan, rois=tuple(rois), warnings=tuple(warnings))

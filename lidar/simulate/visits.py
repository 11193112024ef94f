"""Whole simulated visits: coarse scan, a plan, fine scans; several set-ups in one visit; project-frame exports.

A plan callback ``plan_for(visit_folder, coarse_path) -> list of RoiPlan`` decides the fine windows, so the
product's own planner can be plugged in (``truth_plan_for`` plans from the simulator's truth instead).

Set-ups of one visit (:func:`simulate_setups`) go to ``setup1/``, ``setup2/``... each a visit folder of its own
(own station, own scanner frame, own coarse and fine files), scanned one after the other.

A registered export (:func:`export_registered`) writes a visit's scans in a project frame (a rigid transform
with large offsets, e.g. 2,500,000 / 5,600,000 m) with the transform beside them as ``sop.txt``: the 4x4
matrix taking scanner-frame coordinates to the project frame, rows of four numbers, ``#`` comment lines (as
RiSCAN exports an SOP).
"""
from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from common.errors import InputError
from lidar.io.las import read_las, write_las
from lidar.plan import PlanTarget, RoiPlan, plan_fine_scans
from lidar.simulate.bridge import BridgeModel
from lidar.simulate.effects import VisitTiming
from lidar.simulate.files import load_scene, load_scene_model, simulate_coarse, simulate_fine
from lidar.simulate.scene import BridgeScene, EpochConditions
from lidar.simulate.setup import ScannerSetup
from lidar.simulate.truth import ScanTruth

PlanFor = Callable[[Path, Path], Sequence[RoiPlan]]
#: ``plan_visit(setup_folders, coarse_paths) -> windows of each set-up``: a visit's set-ups planned together.
PlanVisit = Callable[[Sequence[Path], Sequence[Path]], Sequence[Sequence[RoiPlan]]]


@dataclass(frozen=True)
class VisitFiles:
    """What :func:`simulate_visit` wrote: the folder, its scans and the visit's truth (also in ``truth.json``)."""

    folder: Path
    coarse: Path
    fine: Path | None
    truth: ScanTruth


def truth_plan_for(*, min_points: int = 1000, position_noise_m: float = 0.01, closure: str | None = None,
                   seed: int = 0) -> PlanFor:
    """A plan callback planning from the simulator's truth (no coarse-scan processing), for tests and studies.

    Every target whose face turns toward the scanner gets a window (occlusion is not checked), in the
    model's target order.

    Parameters
    ----------
    min_points : int, keyword-only
        Points per target. Default 1000.
    position_noise_m : float, keyword-only
        Error of the positions the planner is given, per axis, metres. Default 0.01.
    closure : str, optional, keyword-only
        A target whose window is scanned again at the end of the visit (``closure=True``). Default none.
    seed : int, keyword-only
        Seed of the position errors. Default 0.

    Returns
    -------
    ``plan_for(visit_folder, coarse_path) -> list of RoiPlan``.
    """

    def plan_for(folder: Path, coarse: Path) -> list[RoiPlan]:
        setup, conditions, _, _ = load_scene(folder)
        scene = BridgeScene(load_scene_model(folder), conditions, setup)
        rng = np.random.default_rng(seed)
        targets = []
        for t in scene.truth().targets:
            c = np.asarray(t.centre_socs_m)
            facing = -float(np.asarray(t.normal_socs) @ (c / np.linalg.norm(c)))
            if facing <= 0.05:  # its face turned away from the scanner: nothing to plan
                continue
            targets.append(PlanTarget(t.id, t.group, tuple(c + rng.normal(0, position_noise_m, 3)),
                                      scene.model.target(t.id).diameter_m, False, facing))
        rois = list(plan_fine_scans(targets, min_points=min_points).rois)
        if closure is not None:
            first = next((r for r in rois if r.reflector == closure), None)
            if first is None:
                raise InputError(f"closure target {closure!r} has no window in the plan")
            rois.append(replace(first, closure=True))
        return rois

    return plan_for


def simulate_visit(folder: str | os.PathLike, *, setup: ScannerSetup, conditions: EpochConditions,
                   plan_for: PlanFor, model: BridgeModel | None = None, seed: int = 0,
                   coarse_step_deg: float = 0.04) -> VisitFiles:
    """One set-up's visit in ``folder``: ``coarse.laz``, the plan callback's windows in ``fine.laz``, the truth.

    ``truth.json`` ends up holding the visit's truth (the fine windows' view with every scan's time span);
    without windows it stays the coarse scan's. ``scene.json`` holds what it was made from.
    """
    folder = Path(folder)
    coarse, truth = simulate_coarse(folder, setup=setup, conditions=conditions, model=model, seed=seed,
                                    coarse_step_deg=coarse_step_deg)
    rois = list(plan_for(folder, coarse))
    if not rois:
        return VisitFiles(folder, coarse, None, truth)
    fine, truth = simulate_fine(folder, rois, model=model, truth_name="truth.json")
    return VisitFiles(folder, coarse, fine, truth)


def visit_end_s(truth: ScanTruth) -> float:
    """When the last scan of a timed visit ended, seconds (from its truth's windows)."""
    if not truth.windows:
        raise InputError("the visit is not timed: its truth records no scan times")
    return max(w.end_s for w in truth.windows)


def simulate_setups(folder: str | os.PathLike, setups: Sequence[ScannerSetup], conditions: EpochConditions, *,
                    plan_for: PlanFor, model: BridgeModel | None = None, seed: int = 0,
                    coarse_step_deg: float = 0.04, move_s: float = 600.0,
                    plan_visit: PlanVisit | None = None) -> list[VisitFiles]:
    """Several set-ups in one visit: ``folder/setup1``, ``folder/setup2``... each with its own station's scans.

    The bridge is in the same state for all of them. When the conditions are timed, set-up k+1 starts
    ``move_s`` seconds after set-up k's last scan and its drift starts afresh (the instrument is levelled
    again); each set-up draws its own noise (seed + k).

    ``plan_visit`` plans the set-ups together: every set-up's coarse scan first, then the windows of all of them
    from ``plan_visit(folders, coarse_paths)``, then each set-up's fine scans (``plan_for`` is then not called).
    With two instruments, or coarse scans kept from the visit before, that is the order of the work; the
    conditions must then be untimed (one instrument's drift and timing follow the order of its scans).
    """
    if not setups:
        raise InputError("no set-ups to simulate")
    if plan_visit is not None:
        return _simulate_together(Path(folder), setups, conditions, plan_visit=plan_visit, model=model, seed=seed,
                                  coarse_step_deg=coarse_step_deg)
    out: list[VisitFiles] = []
    cond = conditions
    for k, setup in enumerate(setups):
        v = simulate_visit(Path(folder) / f"setup{k + 1}", setup=setup, conditions=cond, plan_for=plan_for,
                           model=model, seed=seed + k, coarse_step_deg=coarse_step_deg)
        out.append(v)
        if cond.timed:
            cond = replace(cond, timing=replace(cond.visit_timing, start_s=visit_end_s(v.truth) + move_s))
    return out


def _simulate_together(folder: Path, setups: Sequence[ScannerSetup], conditions: EpochConditions, *,
                       plan_visit: PlanVisit, model: BridgeModel | None, seed: int, coarse_step_deg: float
                       ) -> list[VisitFiles]:
    """:func:`simulate_setups` with the set-ups planned together (every coarse scan before any plan)."""
    if conditions.timed:
        raise InputError("set-ups planned together are simulated with untimed conditions only (the timing of one "
                         "instrument's scans follows the order of its set-ups)")
    folders = [folder / f"setup{k + 1}" for k in range(len(setups))]
    coarse = [simulate_coarse(f, setup=s, conditions=conditions, model=model, seed=seed + k,
                              coarse_step_deg=coarse_step_deg) for k, (f, s) in enumerate(zip(folders, setups,
                                                                                              strict=True))]
    windows = list(plan_visit(folders, [c for c, _ in coarse]))
    if len(windows) != len(setups):
        raise InputError(f"the visit's plan has windows for {len(windows)} set-ups, not {len(setups)}")
    out = []
    for f, (c, truth), rois in zip(folders, coarse, windows, strict=True):
        if rois:
            fine, truth = simulate_fine(f, list(rois), model=model, truth_name="truth.json")
            out.append(VisitFiles(f, c, fine, truth))
        else:
            out.append(VisitFiles(f, c, None, truth))
    return out


def project_transform(rng: np.random.Generator, *, origin_m: ArrayLike = (2_500_000.0, 5_600_000.0, 100.0),
                      tilt_deg: float = 0.0, spread_m: float = 50.0) -> np.ndarray:
    """A random rigid transform (scanner frame -> project frame) with large offsets, as a 4x4 matrix.

    Parameters
    ----------
    rng : numpy Generator
    origin_m : (3,) project coordinates the translation is drawn around, metres. Default (2.5e6, 5.6e6, 100).
    tilt_deg : float, keyword-only
        Standard deviation of the tilts about x and y, degrees (0: the project's z is the scanner's). Default 0.
    spread_m : float, keyword-only
        Uniform spread of the translation around ``origin_m`` per axis, metres. Default 50.

    Returns
    -------
    (4, 4) float64.
    """
    angles = [rng.uniform(0.0, 360.0), rng.normal(0.0, tilt_deg), rng.normal(0.0, tilt_deg)] if tilt_deg \
        else [rng.uniform(0.0, 360.0), 0.0, 0.0]
    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("ZYX", angles, degrees=True).as_matrix()
    m[:3, 3] = np.asarray(origin_m, dtype=np.float64) + rng.uniform(-spread_m, spread_m, 3)
    return m


def write_sop(path: str | os.PathLike, sop: ArrayLike, *, comment: str = "") -> Path:
    """Write a 4x4 SOP (scanner frame -> project frame) as text: ``#`` comment lines, four numbers a row."""
    m = np.asarray(sop, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise InputError("an SOP is a finite 4x4 matrix")
    lines = ["# SOP: scanner's own coordinate system -> project frame (4x4, row by row)"]
    lines += [f"# {c}" for c in comment.splitlines() if c.strip()]
    lines += [" ".join(f"{v:.12f}" if abs(v) < 10 else f"{v:.6f}" for v in row) for row in m]
    p = Path(path)
    p.write_text("\n".join(lines) + "\n")
    return p


def read_sop(path: str | os.PathLike) -> np.ndarray:
    """The 4x4 matrix written by :func:`write_sop` (``#`` lines and blank lines skipped)."""
    p = Path(path)
    rows = [line.split() for line in p.read_text().splitlines() if line.strip() and not line.lstrip().startswith("#")]
    try:
        m = np.array([[float(v) for v in r] for r in rows], dtype=np.float64)
    except ValueError:
        raise InputError(f"{p}: an SOP holds four numbers a row") from None
    if m.shape != (4, 4):
        raise InputError(f"{p}: an SOP is 4 rows of 4 numbers, got shape {m.shape}")
    return m


def export_registered(visit_folder: str | os.PathLike, out_folder: str | os.PathLike, sop: ArrayLike, *,
                      names: Sequence[str] = ("coarse.laz", "fine.laz")) -> dict[str, Path]:
    """Write a visit's scans transformed into a project frame, with ``sop.txt`` beside them.

    Parameters
    ----------
    visit_folder : path-like
        A visit folder (scanner-frame scans).
    out_folder : path-like
        Where the project-frame files go (same names), with ``sop.txt`` and copies of ``truth.json`` and
        ``scene.json`` (both still in the bridge and scanner frames).
    sop : (4, 4) array
        Scanner frame -> project frame.
    names : sequence of str, keyword-only
        The scan files to export, those present. Default coarse.laz and fine.laz.

    Returns
    -------
    {name: path} of every file written, ``"sop"`` for the matrix.
    """
    m = np.asarray(sop, dtype=np.float64)
    if m.shape != (4, 4) or not np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-9):
        raise InputError("the SOP must be a rigid 4x4 transform")
    src, out = Path(visit_folder), Path(out_folder)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    for name in names:
        if not (src / name).is_file():
            continue
        scan = read_las(src / name)
        xyz = scan.xyz_socs @ m[:3, :3].T + m[:3, 3]
        moved = replace(scan, xyz_socs=np.ascontiguousarray(xyz), pose=None)
        written[name] = write_las(moved, out / name)
    for name in ("truth.json", "scene.json"):
        if (src / name).is_file():
            written[name] = Path(shutil.copyfile(src / name, out / name))
    written["sop"] = write_sop(out / "sop.txt", m, comment=f"visit {src.name}; scans in this folder are in the "
                                                           "project frame")
    return written


def timed(conditions: EpochConditions, *, start_s: float = 0.0, gap_s: float = 30.0) -> EpochConditions:
    """The conditions with a visit timing (points get times), keeping any timing already there."""
    return conditions if conditions.timing is not None else replace(conditions, timing=VisitTiming(start_s, gap_s))

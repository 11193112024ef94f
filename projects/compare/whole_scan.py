"""Whole-scan comparison of two epochs of a campaign (the conventional approach, for context).

Both epochs are brought into the campaign frame (the baseline epoch's scanner frame): a rigid
registration on the reference-target centroids, refined by ICP on the stable parts (piers and
the ground around them, below the deck). Then cloud-to-cloud or M3C2 change, and a span
profile along the girder lines next to the target displacements of the same epochs.
"""
from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import laspy
import numpy as np
from scipy.spatial import cKDTree

from common.errors import InputError
from common.files import atomic_output, output_folder, write_atomic
from common.progress import ProgressCallback, report, scaled
from lidar.figures import save_figure
from lidar.io import read_scans
from lidar.io.stream import open_stream
from projects.compare.figures import span_profile_figure
from projects.compare.span import SpanFrame, pivot, span_frame
from projects.processing.stages import baseline_epoch, layout_up, parameters, read_files
from projects.results.table import displacement_table
from projects.store.campaign import Campaign
from projects.store.errors import CampaignError
from projects.store.records import now_iso
from registration.change import METHODS, ChangeResult, cloud_to_cloud, core_points_grid, m3c2, prefetch_py4dgeo
from registration.icp import IcpResult, refine_icp, stable_mask
from registration.ndt import refine_ndt
from registration.profile import SpanProfile, girder_lines, span_profile
from registration.targets import TargetRegistration, register_targets
from registration.transform import Transform, pose_difference

if TYPE_CHECKING:
    from registration.profile import RegistrationSigma

SUMMARY_VERSION = 1


@dataclass(frozen=True)
class ChangeOptions:
    """How the change is computed, with py4dgeo's parameter names (metres).

    Attributes
    ----------
    normal_radii : tuple of float
        M3C2 normal radii (default 0.5 m; several: multi-scale).
    cyl_radius : float
        M3C2 projection cylinder radius (default 0.25 m).
    max_distance : float
        M3C2 cylinder half-length, and the C2C search distance (default 0.5 m for M3C2; C2C keeps 1 m unless
        given).
    corepoints : float or path
        A grid step (default 0.25 m: one core point per occupied cube of the first epoch) or a point file.
    registration_error : float or None
        Given (metres), or None: measured, the two target registrations' RMS combined.
    robust_aggr : bool
        M3C2 median and inter-quartile spread instead of mean and standard deviation.
    """

    normal_radii: tuple[float, ...] = (0.5,)
    cyl_radius: float = 0.25
    max_distance: float | None = None
    corepoints: float | Path = 0.25
    registration_error: float | None = None
    robust_aggr: bool = False

    def check(self) -> ChangeOptions:
        """The options, or InputError naming the first impossible one (before any computing)."""
        for name, v in (("--normal-radii", min(self.normal_radii, default=float("nan"))),
                        ("--cyl-radius", self.cyl_radius), ("--max-distance", self.max_distance)):
            if v is not None and not (np.isfinite(v) and v > 0):
                raise InputError(f"{name} must be positive metres, got {v}")
        if self.registration_error is not None and not (np.isfinite(self.registration_error)
                                                        and self.registration_error >= 0):
            raise InputError(f"--registration-error must be zero or positive metres, got {self.registration_error}")
        if isinstance(self.corepoints, Path):
            open_stream(self.corepoints)  # a missing or damaged file: one line now, not after the registration
        elif not (np.isfinite(self.corepoints) and self.corepoints > 0):
            raise InputError(f"--corepoints must be a positive grid step in metres or a point file, "
                             f"got {self.corepoints}")
        return self

    def core_points(self, xyz_first: np.ndarray) -> tuple[np.ndarray, str]:
        """Core points in the campaign frame, and how they were chosen."""
        if isinstance(self.corepoints, Path):
            pts = np.vstack([s.xyz_socs for s in read_scans(self.corepoints)])
            return pts, f"file {self.corepoints} ({len(pts)} points, campaign frame)"
        return core_points_grid(xyz_first, float(self.corepoints)), f"grid of {self.corepoints:g} m"


@dataclass(frozen=True, eq=False)
class EpochInFrame:
    """One epoch brought into the campaign frame."""

    label: str
    registration: TargetRegistration | None  # None for the baseline itself
    icp: IcpResult | None
    transform: Transform                        # epoch SOCS -> campaign frame
    xyz: np.ndarray                             # coarse scan in the campaign frame


def _centroid_arrays(c: Campaign, label: str, ids) -> tuple[np.ndarray, np.ndarray]:
    cents = c.centroids(label)
    xyz = np.array([cents[i].xyz_socs if i in cents and cents[i].found else np.full(3, np.nan) for i in ids])
    sig = np.array([float(np.sqrt(np.trace(cents[i].cov))) if i in cents and cents[i].found else np.nan for i in ids])
    return xyz, sig


def _below_deck_m(meas_xyz: np.ndarray) -> float | None:
    """Height limit of the stable parts: half a metre below the lowest deck target (None if none was seen)."""
    z = meas_xyz[:, 2]
    return float(np.nanmin(z) - 0.5) if np.isfinite(z).any() else None


#: Refinements of the target registration on the stable parts.
REFINEMENTS = ("icp", "ndt", "targets")


def bring_to_campaign_frame(c: Campaign, label: str, base: str, *, refinement: str = "icp", base_xyz=None,
                            progress: ProgressCallback | None = None) -> EpochInFrame:
    """Register epoch ``label`` onto the baseline epoch ``base`` (targets, then ICP or NDT on stable parts).

    ``refinement`` is ``icp`` (point-to-plane, the default), ``ndt`` (PCL's
    pcl_ndt3d) or ``targets`` (no refinement). ``base_xyz``, the baseline's
    coarse scan, is read here when not given.
    """
    if refinement not in REFINEMENTS:
        raise InputError(f"unknown registration refinement {refinement!r}; use {', '.join(REFINEMENTS)}")
    refine = refinement != "targets"
    if base_xyz is None and (label == base or refine):
        base_xyz = read_files(c, c.files(base, "coarse"), what="the whole-scan comparison").xyz_socs
    if label == base:
        return EpochInFrame(label, None, None, Transform.identity("campaign"), base_xyz)
    if not c.centroids(label) or not c.centroids(base):
        raise CampaignError(f"epochs {label} and {base} need measured targets for the registration; "
                            "add their fine scans and run 'bridgesurvey process'")
    report(progress, 0.0, f"reading {label}")
    scan = read_files(c, c.files(label, "coarse"), scaled(progress, 0.0, 0.3),
                      what="the whole-scan comparison")
    layout = c.layout()
    refs = layout.ids_in("reference")
    src, s1 = _centroid_arrays(c, label, refs)
    dst, s2 = _centroid_arrays(c, base, refs)
    tr = register_targets(src, dst, refs, sigma_m=np.hypot(s1, s2), source_frame=f"socs:{label}",
                          target_frame="campaign")
    tf, icp = tr.transform, None
    if refine:
        meas = layout.ids_in("measurement")
        used = np.isfinite(src[:, 0]) & np.isfinite(dst[:, 0])
        mask_src = stable_mask(scan.xyz_socs, src[used],
                               exclude_above_m=_below_deck_m(_centroid_arrays(c, label, meas)[0]))
        mask_dst = stable_mask(base_xyz, dst[used], exclude_above_m=_below_deck_m(_centroid_arrays(c, base, meas)[0]))
        report(progress, 0.4, f"{refinement.upper()} on stable parts")
        refine_fn = refine_ndt if refinement == "ndt" else refine_icp
        icp = refine_fn(scan.xyz_socs[mask_src], base_xyz[mask_dst], tr.transform, progress=scaled(progress, 0.4, 0.95))
        tf = icp.transform
    return EpochInFrame(label, tr, icp, tf, tf.apply(scan.xyz_socs))


def _deck_mask(xyz: np.ndarray, targets: np.ndarray, radius_m: float = 1.0, band_m: float = 0.15) -> np.ndarray:
    t = targets[np.isfinite(targets[:, 0])]
    d, k = cKDTree(t[:, :2]).query(xyz[:, :2], distance_upper_bound=radius_m)
    ok = np.isfinite(d)
    out = np.zeros(len(xyz), bool)
    out[ok] = np.abs(xyz[ok, 2] - t[k[ok], 2]) <= band_m
    return out


def _prefetch() -> None:
    """Import py4dgeo's compiled core and matplotlib's drawing back end in the background while the epochs are read."""
    prefetch_py4dgeo("matplotlib.backends.backend_agg")


def compare_epochs(c: Campaign, from_label: str, to_label: str, *, method: str = "m3c2", refinement: str = "icp",
                   bin_m: float = 2.5, options: ChangeOptions = ChangeOptions(),
                   progress: ProgressCallback | None = None) -> dict:
    """Register two epochs into the campaign frame and compute their change and span profile.

    ``options`` holds the M3C2/C2C parameters (py4dgeo's names). Returns a JSON-ready summary; the arrays are
    under the private key ``_arrays``.
    """
    if method not in METHODS:
        raise InputError(f"unknown comparison method {method!r}; use c2c or m3c2")
    options.check()
    for lab in (from_label, to_label):
        c.epoch(lab)
    if from_label == to_label:
        raise InputError("--from and --to must be two different epochs")
    base = baseline_epoch(c)
    if base is None:
        raise CampaignError("no measured epoch yet: process the campaign first ('bridgesurvey process')")
    if method == "m3c2":
        _prefetch()
    report(progress, 0.0, f"reading {base}")
    base_xyz = read_files(c, c.files(base, "coarse"), what="the whole-scan comparison").xyz_socs  # once, for both epochs
    ea = bring_to_campaign_frame(c, from_label, base, refinement=refinement, base_xyz=base_xyz,
                                 progress=scaled(progress, 0.05, 0.35))
    eb = bring_to_campaign_frame(c, to_label, base, refinement=refinement, base_xyz=base_xyz,
                                 progress=scaled(progress, 0.35, 0.7))
    layout = c.layout()
    refs, meas = layout.ids_in("reference"), layout.ids_in("measurement")
    ref_base, _ = _centroid_arrays(c, base, refs)
    meas_from, _ = _centroid_arrays(c, from_label, meas)
    meas_from = ea.transform.apply(meas_from)
    measured_err = float(np.sqrt(sum((e.registration.rms_m if e.registration else 0.0) ** 2 for e in (ea, eb))))
    reg_err = measured_err if options.registration_error is None else float(options.registration_error)
    # The region worth comparing: the bridge (targets) and 5 m around it, ground included.
    anchors = np.vstack([ref_base[np.isfinite(ref_base[:, 0])], meas_from[np.isfinite(meas_from[:, 0])]])
    lo, hi = anchors.min(axis=0) - 5.0, anchors.max(axis=0) + 5.0
    lo[2] = anchors[:, 2].min() - 10.0

    def crop(x):
        return x[np.all((x >= lo) & (x <= hi), axis=1)]

    xa, xb = crop(ea.xyz), crop(eb.xyz)
    report(progress, 0.72, f"change ({method})")
    core_how = None
    if method == "m3c2":
        core, core_how = options.core_points(xa)
        change = m3c2(xa, xb, core, normal_radii=options.normal_radii, cyl_radius=options.cyl_radius,
                      max_distance=options.max_distance or 0.5, registration_error=reg_err,
                      robust_aggr=options.robust_aggr, progress=scaled(progress, 0.72, 0.92))
    else:
        change = cloud_to_cloud(xa, xb, max_distance_m=options.max_distance or 1.0, registration_error_m=reg_err)
    parameters = {**change.parameters, "registration_error_source":
                  "measured: the target registrations' RMS" if options.registration_error is None else "given"}
    if core_how:
        parameters["corepoints_from"] = core_how
    stable = stable_mask(change.points, ref_base[np.isfinite(ref_base[:, 0])], exclude_above_m=_below_deck_m(meas_from))
    deck = _deck_mask(change.points, meas_from)
    report(progress, 0.93, "span profile")
    prof, frame = _profile(c, base, (ea, eb), (xa, xb), bin_m=bin_m)
    # target displacements of the same two epochs, at their stations along the span
    rows = {(r["epoch"], r["reflector"]): r for r in displacement_table(c)}
    targets = []
    for rid, p in zip(meas, meas_from, strict=False):
        a, b = rows.get((from_label, rid)), rows.get((to_label, rid))
        if a and b and a["displacement_mm"] is not None and b["displacement_mm"] is not None and np.isfinite(p[0]):
            s_m, l_m, _ = frame.coords(p[None])[0]
            targets.append({"reflector": rid, "station_m": float(s_m),
                            "girder": int(prof.girder_of(np.array([l_m]))[0]) + 1,
                            "displacement_mm": b["displacement_mm"] - a["displacement_mm"],
                            "sigma_mm": float(np.hypot(a["sigma_mm"] or 0, b["sigma_mm"] or 0))})
    summary = {
        "version": SUMMARY_VERSION, "from": from_label, "to": to_label, "baseline": base, "method": method,
        "frame": f"campaign (scanner frame of baseline epoch {base})",
        "registration": {e.label: _registration_json(e) for e in (ea, eb)},
        "registration_error_mm": reg_err * 1e3,
        "change": {"all": {**change.summary(), "computed_on": PARTS["all"]},
                   "stable_parts": {**change.summary(stable), "computed_on": PARTS["stable_parts"]},
                   "deck": {**change.summary(deck), "computed_on": PARTS["deck"]},
                   "parameters": parameters},
        "span_profile": _profile_json(prof, frame),
        "targets": targets, "created": now_iso(),
    }
    summary["_arrays"] = {"change": change, "profile": prof}
    report(progress, 1.0, "compared")
    return summary


def _profile(c: Campaign, base: str, epochs: tuple[EpochInFrame, EpochInFrame], clouds: tuple[np.ndarray, np.ndarray],
             *, bin_m: float) -> tuple[SpanProfile, SpanFrame]:
    """The span profile of two epochs in span coordinates tied to the layout, with their registration σ."""
    layout = c.layout()
    ids = list(layout.ids)
    base_xyz, _ = _centroid_arrays(c, base, ids)
    frame = span_frame(layout, ids, base_xyz, layout_up(parameters(c)))
    meas = layout.ids_in("measurement")
    refs = layout.ids_in("reference")
    from_xyz, _ = _centroid_arrays(c, epochs[0].label, meas)
    slh_targets = frame.coords(epochs[0].transform.apply(from_xyz))
    lay_slh = frame.from_layout(np.array([layout.xyz[layout.index(i)] for i in meas]))
    lines = girder_lines(lay_slh[:, :2], slh_targets[:, 2])
    sig: list[RegistrationSigma | None] = []
    for e in epochs:
        if e.registration is None:
            sig.append(None)
            continue
        ref_xyz, _ = _centroid_arrays(c, base, refs)
        used = np.array([r.used for r in e.registration.residuals])
        sig.append(frame.registration_sigma(e.transform, pivot(ref_xyz, used)))
    prof = span_profile(frame.coords(clouds[0]), frame.coords(clouds[1]), lines,
                        stations_m=(frame.first_pier_m, frame.last_pier_m), bin_m=bin_m,
                        registration=(sig[0], sig[1]))
    return prof, frame


def _profile_json(prof: SpanProfile, frame: SpanFrame) -> dict:
    return {"bin_m": prof.bin_m, "frame": "layout: station along the layout's x from its first pier, lateral "
                                          "offset, height along the layout's up",
            "girder_offsets_m": list(prof.girder_offsets_m), "first_pier_station_m": frame.first_pier_m,
            "last_pier_station_m": frame.last_pier_m, "selection": {
                "half_width_m": prof.half_width_m, "band_m": prof.band_m, "max_tilt_deg": prof.max_tilt_deg,
                "underside_extent_m": list(prof.underside_extent_m)},
            "notes": list(prof.notes), "bins": prof.table()}


#: What each part of the change statistics is computed on.
PARTS = {"stable_parts": "the stable parts (piers and the ground around them, below the deck)",
         "deck": "the deck underside within 1 m of a measurement target",
         "all": "everything compared (the bridge and 5 m around it)"}


def _registration_json(e: EpochInFrame) -> dict:
    if e.registration is None:
        return {"role": "baseline (defines the campaign frame)", "transform": e.transform.to_json()}
    used = len(e.registration.used_ids)
    out = {"targets": {"rms_mm": e.registration.rms_m * 1e3,
                       "rms_on": f"{used} reference targets (tie-point residuals after the fit)",
                       "mode": e.registration.mode, "residuals": e.registration.table(),
                       "warnings": list(e.registration.warnings)},
           "transform": e.transform.to_json()}
    if e.icp is not None:
        dt_m, dr_deg = pose_difference(e.registration.transform, e.icp.transform)
        voxel_cm = e.icp.voxels_m[-1] * 100
        out["icp"] = {"method": e.icp.correction.method, "fitness": e.icp.fitness,
                      "rms_mm": e.icp.rms_m * 1e3,
                      "rms_on": f"stable parts, {e.icp.n_source} / {e.icp.n_target} points at {voxel_cm:.0f} cm "
                                "voxels: point-to-point distance of the correspondences (of the order of the voxel "
                                "size, not a registration error)",
                      "plane_rms_mm": e.icp.plane_rms_m * 1e3,
                      "plane_rms_on": "stable parts, the same correspondences: distance to the surface's plane",
                      "iterations": list(e.icp.iterations),
                      "voxels_m": list(e.icp.voxels_m), "points": [e.icp.n_source, e.icp.n_target],
                      "change_from_targets_mm": dt_m * 1e3, "change_from_targets_deg": dr_deg}
    return out


def registration_lines(summary: dict) -> list[tuple[str, str]]:
    """(epoch label, line) per registered epoch: each RMS and what it is computed on (CLI and report)."""
    lines = []
    for lab, reg in summary["registration"].items():
        if "targets" not in reg:
            continue
        t = reg["targets"]
        text = f"{lab}: target registration RMS {t['rms_mm']:.2f} mm on {t.get('rms_on', 'the reference targets')}"
        icp = reg.get("icp")
        if icp:
            name = icp.get("method", "icp").upper()
            plane = icp.get("plane_rms_mm")
            text += (f"; {name} on the stable parts: fitness {icp['fitness']:.2f}, "
                     + (f"point-to-plane RMS {plane:.1f} mm, " if plane is not None and np.isfinite(plane) else "")
                     + f"correspondence distance RMS {icp['rms_mm']:.1f} mm (point-to-point at "
                     f"{icp['voxels_m'][-1] * 100:.0f} cm voxels), iterations "
                     f"{'/'.join(map(str, icp['iterations']))}, moved the pose {icp['change_from_targets_mm']:.2f} mm")
        lines.append((lab, text))
    return lines


def change_lines(summary: dict) -> list[str]:
    """One line per part of the change statistics, saying what it is computed on (CLI)."""
    out = []
    what = "M3C2 core points" if summary["method"] == "m3c2" else "compared points"
    for part in ("stable_parts", "deck", "all"):
        s = summary["change"][part]
        if s["n"]:
            out.append(f"{part.replace('_', ' ')}: median {s['median_mm']:+.2f} mm, RMS {s.get('rms_mm', float('nan')):.2f} "
                       f"mm, std {s['std_mm']:.2f} mm over {s['n']} {what} on "
                       + s.get("computed_on", PARTS[part])
                       + (f"; median LoD {s['median_lod_mm']:.2f} mm" if s.get("median_lod_mm") is not None else ""))
    return out


def write_outputs(summary: dict, out_dir: str | os.PathLike) -> list[Path]:
    """change.laz (distances as extra dimensions), summary.json, registration.csv, span_profile.csv/.png."""
    out = output_folder(out_dir)
    arrays = summary["_arrays"]
    public = {k: v for k, v in summary.items() if k != "_arrays"}
    paths = [write_change_las(arrays["change"], out / "change.laz"),
             write_atomic(out / "summary.json", json.dumps(public, indent=2, default=float))]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["epoch", "target", "dx_mm", "dy_mm", "dz_mm", "residual_mm", "leave_one_out_mm", "used", "fits"])
    for lab, reg in public["registration"].items():
        for r in reg.get("targets", {}).get("residuals", []):
            w.writerow([lab, r["target"], *(f"{r[k]:.3f}" for k in ("dx_mm", "dy_mm", "dz_mm", "residual_mm",
                                                                     "leave_one_out_mm")), r["used"], r["fits"]])
    paths.append(write_atomic(out / "registration.csv", buf.getvalue()))
    buf = io.StringIO()
    bins = public["span_profile"]["bins"]
    if bins:
        dw = csv.DictWriter(buf, fieldnames=list(bins[0]), lineterminator="\n")
        dw.writeheader()
        dw.writerows(bins)
    paths.append(write_atomic(out / "span_profile.csv", buf.getvalue()))
    paths.append(save_figure(span_profile_figure(public), out / "span_profile.png"))
    return paths


def write_change_las(change: ChangeResult, path: Path) -> Path:
    """Write a comparison's points with their change (mm) as extra dimensions of a LAS file; returns its path."""
    hdr = laspy.LasHeader(point_format=6, version="1.4")
    hdr.scales = np.array([1e-4, 1e-4, 1e-4])
    hdr.offsets = np.floor(change.points.min(axis=0))
    hdr.add_extra_dims([laspy.ExtraBytesParams(name=f"{change.method}_distance_mm", type=np.float32),
                        laspy.ExtraBytesParams(name="lod_mm", type=np.float32),
                        laspy.ExtraBytesParams(name="significant", type=np.uint8)])
    las = laspy.LasData(hdr)
    las.x, las.y, las.z = change.points[:, 0], change.points[:, 1], change.points[:, 2]
    las[f"{change.method}_distance_mm"] = (change.distance_m * 1e3).astype(np.float32)
    lod = change.lod_m if change.lod_m is not None else np.full(len(change.points), change.registration_error_m)
    las["lod_mm"] = (lod * 1e3).astype(np.float32)
    las["significant"] = change.significant.astype(np.uint8)
    with atomic_output(path) as tmp:
        las.write(tmp)
    return path


def save_comparison(c: Campaign, summary: dict) -> None:
    """Keep a comparison's summary (without its arrays) in the campaign, for reports."""
    c.comparisons.save({k: v for k, v in summary.items() if k != "_arrays"})


def comparisons(c: Campaign, epochs: set | None = None) -> list[dict]:
    """Stored comparison summaries (newest versions this BridgeSurvey reads), optionally within some epochs."""
    out = []
    for s in (r.summary for r in c.comparisons.all()):
        if int(s.get("version", 0)) > SUMMARY_VERSION:
            continue
        if epochs is None or (s["from"] in epochs and s["to"] in epochs):
            out.append(s)
    return out

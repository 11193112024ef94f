"""A reduced reflectance map with its detections, stored with each planned epoch.

Reports and the desktop application show every epoch's map without reading
its coarse scan again (a few hundred kB per epoch instead of a few GB of
points). The stored form is a versioned ``.npz`` blob plus JSON annotations.
"""
from __future__ import annotations

import io
import json
from dataclasses import asdict, dataclass

import numpy as np

from lidar.detection import Detection, DetectionResult
from lidar.identification import Identification, TargetMatch
from lidar.reflectance_map import ReflectanceMap, reduce_map
from projects.store.errors import CampaignError

PREVIEW_VERSION = 1
#: Cells kept per stored map: about 1600 x 600, enough to see every target of a coarse scan.
PREVIEW_CELLS = 1_000_000


@dataclass(frozen=True, eq=False)
class MapPreview:
    """What the coarse scan of an epoch showed: reduced map, detections and identified reflectors."""

    reflectance_map: ReflectanceMap
    detections: DetectionResult
    identification: Identification
    full_step_deg: float


def encode_preview(analysis) -> tuple[bytes, str]:
    """Blob and JSON text of a :class:`lidar.pipeline.CoarseAnalysis`."""
    full = analysis.reflectance_map
    r = reduce_map(full, max_cells=PREVIEW_CELLS)
    buf = io.BytesIO()
    with np.errstate(invalid="ignore"):
        q = np.where(np.isnan(r.max_intensity), 255, np.clip(np.round(r.max_intensity * 254), 0, 254)).astype(np.uint8)
    np.savez_compressed(buf, version=np.int32(PREVIEW_VERSION), max_intensity_u8=q,
                        range_m=r.range_m.astype(np.float16), count=r.count,
                        geometry=np.array([r.theta0_deg, r.phi0_deg, r.step_deg, float(r.full_circle), r.n_points,
                                           full.step_deg]))
    ident = analysis.identification
    det = analysis.detections
    notes = {"version": PREVIEW_VERSION,
             "detections": [asdict(d) for d in det.detections], "threshold": det.threshold,
             "matches": [asdict(m) for m in ident.matches], "rotation": np.asarray(ident.rotation).tolist(),
             "translation": np.asarray(ident.translation).tolist(), "rms_m": ident.rms_m,
             "extra_detections": list(ident.extra_detections)}
    return buf.getvalue(), json.dumps(notes, default=float)


def decode_preview(blob: bytes, annotations: str) -> MapPreview:
    """Inverse of :func:`encode_preview`; refuses a newer stored version."""
    z = np.load(io.BytesIO(blob))
    notes = json.loads(annotations)
    version = int(z["version"])
    if version > PREVIEW_VERSION or int(notes.get("version", 0)) > PREVIEW_VERSION:
        raise CampaignError(f"stored map preview version {version} is newer than this BridgeSurvey reads "
                            f"({PREVIEW_VERSION}); update BridgeSurvey")
    theta0, phi0, step, full, n, full_step = z["geometry"]
    q = z["max_intensity_u8"]
    mx = np.where(q == 255, np.nan, q / 254.0).astype(np.float32)
    rng = z["range_m"].astype(np.float32)
    rmap = ReflectanceMap(float(theta0), float(phi0), float(step), mx, mx.copy(), rng, z["count"], bool(full), int(n))
    dets = tuple(Detection(**{**d, "xyz_socs": tuple(d["xyz_socs"])}) for d in notes["detections"])
    det = DetectionResult(dets, (), float(notes["threshold"]), float(full_step))
    matches = tuple(TargetMatch(**{**m, "xyz_socs": tuple(m["xyz_socs"])}) for m in notes["matches"])
    ident = Identification(matches, np.array(notes["rotation"]), np.array(notes["translation"]),
                           float(notes["rms_m"]), tuple(notes["extra_detections"]))
    return MapPreview(rmap, det, ident, float(full_step))

"""Ground-truth records of simulated scans (what the processing must recover)."""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Optional

import numpy as np

TRUTH_FORMAT_VERSION = 1


@dataclass(frozen=True)
class TargetTruth:
    """A simulated target as it really was in one scan: position, normal, points on it and visibility."""

    id: str
    group: str
    centre_bridge_m: tuple[float, ...]
    centre_socs_m: tuple[float, ...]
    normal_socs: tuple[float, ...]
    vertical_displacement_m: float
    moved: bool = False
    occluded: bool = False
    cable_tie: bool = False
    points_on_target: Optional[int] = None


@dataclass(frozen=True)
class ScanTruth:
    """What a simulated scan really held: the scanner's pose and every target's truth."""

    scanner_pose: np.ndarray  # (4, 4) SOCS -> bridge frame
    midspan_displacement_m: float
    targets: tuple[TargetTruth, ...]
    removed: tuple[str, ...] = ()
    range_noise_m: float = 0.005

    def target(self, target_id: str) -> TargetTruth:
        return next(t for t in self.targets if t.id == target_id)

    def to_dict(self) -> dict:
        return {
            "format_version": TRUTH_FORMAT_VERSION,
            "scanner_pose": np.asarray(self.scanner_pose).tolist(),
            "midspan_displacement_m": self.midspan_displacement_m,
            "removed": list(self.removed),
            "range_noise_m": self.range_noise_m,
            "targets": [asdict(t) for t in self.targets],
        }

    @classmethod
    def from_dict(cls, d: dict) -> "ScanTruth":
        targets = tuple(TargetTruth(**{**t, "centre_bridge_m": tuple(t["centre_bridge_m"]),
                                        "centre_socs_m": tuple(t["centre_socs_m"]),
                                        "normal_socs": tuple(t["normal_socs"])}) for t in d["targets"])
        return cls(np.asarray(d["scanner_pose"]), float(d["midspan_displacement_m"]), targets,
                   tuple(d.get("removed", ())), float(d.get("range_noise_m", 0.005)))

    def save(self, path: str | os.PathLike) -> Path:
        p = Path(path)
        p.write_text(json.dumps(self.to_dict(), indent=1))
        return p

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ScanTruth":
        return cls.from_dict(json.loads(Path(path).read_text()))

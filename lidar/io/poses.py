"""Scans in a project frame: the project-frame test, scanner pose files, and the carry into the scanner's frame.

A registered export (RiSCAN PRO after a multi-station adjustment, Cyclone, SCENE) holds its points in a
project or national frame: coordinates of millions of metres, the scanner nowhere near the origin. The
reflectance map, planning and the centroids need the scanner's own frame (SOCS), so such a scan is carried
back by its scanner pose ``P`` (a 4x4 rigid transform, scanner frame -> project frame)::

    x_socs = R^T (x_project - t)        with  P = [[R, t], [0, 0, 0, 1]]

The pose comes from the file itself (an E57 scan's pose, a PTX header), from a pose file
(:func:`read_pose_file`: RiSCAN's SOP export, a Cyclone transformation text) or from the scanner's position
alone (:func:`pose_from_origin`). :class:`FileFrame` records, for one stored file, which of its scans belong
to a set-up and the pose that carries them; :func:`read_in_scanner_frame` reads them so.
"""
from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError
from common.progress import ProgressCallback
from lidar.io import read_scan, read_scans
from lidar.scan import Scan

#: A scan whose nearest point is farther than this from the origin is not in its scanner's frame (metres).
FAR_FROM_SCANNER_M = 2000.0
#: Largest departure of a pose's 3x3 block from a rotation (|R R^T - I|), and of its last row from 0 0 0 1.
ROTATION_TOLERANCE = 1e-6
#: Two poses closer than this (metres, and radians of rotation) are the same scanner position.
SAME_POSE_M = 1e-3
SAME_POSE_RAD = 1e-5
#: How to give a pose, for every message that asks for one.
POSE_HINT = ("give its scanner pose with --pose FILE (the 4x4 scanner-to-project matrix, e.g. RiSCAN's SOP "
             "export) or the scanner's position with --origin X,Y,Z")


def nearest_range_m(xyz: np.ndarray) -> float:
    """Distance of the point nearest the origin (inf for no points), metres."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    return float(np.sqrt(np.min(np.einsum("ij,ij->i", xyz, xyz)))) if len(xyz) else math.inf


def in_project_frame(xyz: np.ndarray) -> bool:
    """Whether points are in a project frame: every one farther than :data:`FAR_FROM_SCANNER_M` from the origin.

    A scanner sees its own surroundings, so a scan in its own frame always has points within a few hundred
    metres of the origin; a project or national frame puts them millions of metres away.

    Examples
    --------
    >>> in_project_frame(np.array([[2.5e6, 5.6e6, 100.0], [2.5e6 + 3, 5.6e6, 101.0]]))
    True
    >>> in_project_frame(np.array([[12.0, -3.0, 1.0], [2.5e6, 5.6e6, 100.0]]))
    False
    """
    return bool(len(np.asarray(xyz).reshape(-1, 3))) and nearest_range_m(xyz) > FAR_FROM_SCANNER_M


def _rigid_problem(m: np.ndarray) -> str | None:
    """Why a 4x4 matrix is not a rigid transform (None when it is)."""
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        return "not a finite 4x4 matrix"
    if np.max(np.abs(m[3] - [0.0, 0.0, 0.0, 1.0])) > ROTATION_TOLERANCE:
        return f"its last row is {' '.join(f'{v:g}' for v in m[3])}, not 0 0 0 1"
    r = m[:3, :3]
    if np.max(np.abs(r @ r.T - np.eye(3))) > ROTATION_TOLERANCE or np.linalg.det(r) < 0:
        return "its 3x3 block is not a rotation (a scale, shear or mirror?)"
    return None


def check_pose(pose: ArrayLike, where: str) -> np.ndarray:
    """A (4, 4) float64 rigid transform, or an :class:`InputError` naming ``where`` and the problem."""
    m = np.asarray(pose, dtype=np.float64)
    why = _rigid_problem(m) if m.shape == (4, 4) else "not a 4x4 matrix"
    if why:
        raise InputError(f"{where}: the pose is {why}; a scanner pose is a rigid 4x4 transform")
    return m


def parse_pose_text(text: str, where: str) -> np.ndarray:
    """The 4x4 scanner -> project matrix of a pose text (see :func:`read_pose_file`)."""
    rows = []
    for n, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        try:
            rows.append([float(v) for v in re.split(r"[\s,;]+", body) if v])
        except ValueError:
            raise InputError(f"{where}, line {n}: {body[:40]!r} is not four numbers; a pose file holds the 4x4 "
                             "scanner-to-project matrix, four numbers a row, '#' comments") from None
    if len(rows) != 4 or any(len(r) != 4 for r in rows):
        shape = f"{len(rows)} rows of {sorted({len(r) for r in rows})} numbers" if rows else "no numbers"
        raise InputError(f"{where}: a pose file holds 4 rows of 4 numbers (the scanner-to-project matrix), "
                         f"found {shape}")
    m = np.array(rows, dtype=np.float64)
    if np.allclose(m[:3, 3], 0.0) and np.max(np.abs(m[3, :3])) > ROTATION_TOLERANCE and abs(m[3, 3] - 1) < 1e-9:
        m = m.T  # the translation in the last row (the PTX header's and some exports' convention)
    why = _rigid_problem(m)
    if why:
        raise InputError(f"{where}: the matrix is {why}; a scanner pose is a rigid 4x4 transform")
    return m


def read_pose_file(path: str | os.PathLike) -> np.ndarray:
    """Read a scanner pose file: the 4x4 matrix taking scanner-frame coordinates into the project frame.

    Rows of four numbers (blanks, tabs, commas or semicolons between them), ``#`` comments and blank
    lines skipped: RiSCAN PRO's SOP export, a Cyclone transformation text, or
    :func:`lidar.simulate.visits.write_sop`. A matrix whose translation stands in the last row (last
    column 0 0 0 1) is taken transposed. Anything else is an :class:`InputError` in one line naming the
    file.

    Returns
    -------
    (4, 4) float64 rigid transform.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: pose file not found; check the path")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise InputError(f"{p}: cannot read the pose file as text ({exc.__class__.__name__})") from None
    return parse_pose_text(text, str(p))


def parse_vector(text: str, what: str) -> np.ndarray:
    """Three comma-separated numbers (``--origin X,Y,Z``, ``--up UX,UY,UZ``) as a (3,) array."""
    try:
        v = np.array([float(x) for x in str(text).split(",")], dtype=np.float64)
    except ValueError:
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"{what} expects three numbers X,Y,Z in metres, got {text!r}")
    return v


def pose_from_origin(origin_m: ArrayLike, up: ArrayLike | None = None) -> np.ndarray:
    """A scanner pose from its position alone: the project's axes at ``origin_m``, tilted so that +z is ``up``.

    The heading stays unknown (the identification finds it), so planned windows' horizontal angles are
    in the project's axes, not the instrument's.

    Parameters
    ----------
    origin_m : (3,) scanner position in the project frame, metres.
    up : (3,), optional
        The scanner's vertical in the project frame. Default +z (the project's heights are vertical).

    Returns
    -------
    (4, 4) float64 scanner -> project.
    """
    o = np.asarray(origin_m, dtype=np.float64)
    m = np.eye(4)
    m[:3, 3] = o
    if up is not None:
        u = np.asarray(up, dtype=np.float64)
        if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
            raise InputError(f"--up must be a non-zero direction X,Y,Z, got {up!r}")
        u = u / np.linalg.norm(u)
        axis = np.cross([0.0, 0.0, 1.0], u)
        s, c = float(np.linalg.norm(axis)), float(u[2])
        if s > 1e-12:
            k = axis / s
            kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            m[:3, :3] = np.eye(3) + s * kx + (1 - c) * (kx @ kx)
        elif c < 0:
            m[:3, :3] = np.diag([1.0, -1.0, -1.0])
    return m


def to_scanner_frame(xyz_project: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(N, 3) project-frame points carried into the scanner's frame by ``pose`` (4x4, scanner -> project)."""
    p = np.asarray(pose, dtype=np.float64)
    return (np.asarray(xyz_project, dtype=np.float64) - p[:3, 3]) @ p[:3, :3]  # R^T (x - t), row-wise


def carry_to_scanner(scan: Scan, pose: np.ndarray) -> Scan:
    """The scan with its points carried from the project frame into the scanner's by ``pose`` (scanner -> project).

    The scan keeps ``pose`` as its pose, so :meth:`lidar.scan.Scan.xyz_world` gives the project coordinates back.
    """
    p = np.asarray(pose, dtype=np.float64)
    return replace(scan, xyz_socs=np.ascontiguousarray(to_scanner_frame(scan.xyz_socs, p)), pose=p)


def same_pose(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Whether two scanner poses (4x4, or None for "no pose") are the same position and orientation."""
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if np.linalg.norm(a[:3, 3] - b[:3, 3]) > SAME_POSE_M:
        return False
    cos = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return math.acos(float(np.clip(cos, -1.0, 1.0))) <= SAME_POSE_RAD


@dataclass(frozen=True, eq=False)
class FileFrame:
    """How the points of one stored file reach a set-up's scanner frame.

    Attributes
    ----------
    scans : tuple of int, optional
        The scans of the file that belong to the set-up (indices in :func:`lidar.io.read_scans` order);
        None: the file's only scan.
    pose : (4, 4) float64 array, optional
        The set-up's scanner pose (scanner -> project) when known: the file's own, a pose file's, or one
        made from ``--origin``.
    carry : bool
        Whether the points are in the project frame and must be carried by ``pose`` (else they are in the
        scanner's frame already and the pose is only recorded).
    source : str
        Where the pose came from: ``"file"`` (the scan's own), ``"pose"`` (a pose file), ``"origin"``, or "".
    given : str
        The pose file's path or the origin as typed, for the record.
    points, dropped_points : int
        Points read for the set-up, and points left out of them because a coordinate was NaN or infinite (what the
        import tells the user; not stored, not part of :attr:`key`).
    """

    scans: tuple[int, ...] | None = None
    pose: np.ndarray | None = None
    carry: bool = False
    source: str = ""
    given: str = ""
    points: int = field(default=0, compare=False)
    dropped_points: int = field(default=0, compare=False)

    def to_json(self) -> dict:
        return {"scans": None if self.scans is None else list(self.scans),
                "pose": None if self.pose is None else np.asarray(self.pose).tolist(), "carry": self.carry,
                "source": self.source, "given": self.given}

    @classmethod
    def from_json(cls, d: dict) -> FileFrame:
        return cls(None if d.get("scans") is None else tuple(int(k) for k in d["scans"]),
                   None if d.get("pose") is None else np.asarray(d["pose"], dtype=np.float64),
                   bool(d.get("carry", False)), str(d.get("source", "")), str(d.get("given", "")))

    @property
    def key(self) -> dict:
        """What decides the points read (for input hashes): the scans chosen and the carrying pose."""
        return {"scans": None if self.scans is None else list(self.scans),
                "carry": np.round(np.asarray(self.pose), 9).tolist() if self.carry and self.pose is not None else None}


def read_in_scanner_frame(path: str | os.PathLike, frame: FileFrame | None = None, *,
                          progress: ProgressCallback | None = None) -> Scan:
    """Read a file's scans of one set-up in the scanner's frame (see :class:`FileFrame`).

    Without a frame, the file must hold one scan (as :func:`lidar.io.read_scan`).
    """
    if frame is None or (frame.scans is None and not frame.carry):
        return read_scan(path, progress=progress)
    if frame.scans is None:
        scans = [read_scan(path, progress=progress)]
    else:
        every = read_scans(path, progress=progress)
        if max(frame.scans) >= len(every):
            raise InputError(f"{path}: holds {len(every)} scans, the set-up expects scan {max(frame.scans) + 1}")
        scans = [every[k] for k in frame.scans]
    if frame.carry and frame.pose is not None:
        scans = [carry_to_scanner(s, frame.pose) for s in scans]
    return scans[0] if len(scans) == 1 else Scan.concatenate(scans, name=scans[0].name)


def _groups(scans: Sequence[Scan]) -> list[list[int]]:
    """The file's scans grouped by pose (one group per scanner position), in file order."""
    groups: list[list[int]] = []
    for k, s in enumerate(scans):
        for g in groups:
            if same_pose(scans[g[0]].pose, s.pose):
                g.append(k)
                break
        else:
            groups.append([k])
    return groups


def _frame_of(path: Path, scans: Sequence[Scan], idx: list[int], given: FileFrame | None,
              fallback: FileFrame | None, several: bool) -> FileFrame:
    """The frame of one pose group of a file (see :func:`file_frames`)."""
    own = scans[idx[0]].pose
    chosen = tuple(idx) if several else None
    far = any(in_project_frame(scans[k].xyz_socs) for k in idx)
    if given is not None:
        frame = replace(given, scans=chosen, carry=True)
    elif not far:
        return FileFrame(chosen, own, False, "file" if own is not None else "")
    elif own is not None and not any(in_project_frame(carry_to_scanner(scans[k], own).xyz_socs) for k in idx):
        return FileFrame(chosen, own, True, "file")
    elif fallback is not None and fallback.pose is not None:
        frame = replace(fallback, scans=chosen, carry=True)
    else:
        km = min(nearest_range_m(scans[k].xyz_socs) for k in idx) / 1000.0
        raise InputError(f"{path}: its points are in a project frame (the nearest is {km:,.0f} km from the "
                         f"origin), not the scanner's own; {POSE_HINT}")
    for k in idx:
        if in_project_frame(carry_to_scanner(scans[k], frame.pose).xyz_socs):  # type: ignore[arg-type]
            km = nearest_range_m(carry_to_scanner(scans[k], frame.pose).xyz_socs) / 1000.0  # type: ignore[arg-type]
            raise InputError(f"{path}: with the pose of {frame.given or 'this set-up'} its points are still "
                             f"{km:,.0f} km from the scanner; the matrix must take scanner coordinates into the "
                             "project frame (RiSCAN's SOP): is it inverted, or another scan position's?")
    return frame


def file_frames(path: str | os.PathLike, *, given: FileFrame | None = None, fallback: FileFrame | None = None,
                progress: ProgressCallback | None = None) -> list[FileFrame]:
    """Read a scan file and say how each of its set-ups reaches its scanner frame; one line when it cannot.

    Scans with different poses (an E57 or PTX of several scan positions) are one set-up each, in file
    order. A set-up whose points are in a project frame (:func:`in_project_frame`) is carried by ``given``
    (a pose the user gave, applied to every scan of the file), else by its own pose when that brings
    the points to the scanner, else by ``fallback`` (the set-up's pose already known), else refused
    with the one line that says how to give the pose. With ``given``, every scan is carried by it.

    Returns
    -------
    list of FileFrame, one per set-up of the file (``scans`` None for a one-scan file).
    """
    p = Path(path)
    scans = read_scans(p, progress=progress)
    groups = _groups(scans)
    several = len(scans) > 1
    if given is not None and len(groups) > 1:
        raise InputError(f"{p}: holds {len(groups)} scan positions with their own poses; one --pose cannot carry "
                         "them all (import it without --pose, or one scan position a file)")
    return [replace(_frame_of(p, scans, g, given, fallback, several), points=sum(len(scans[k]) for k in g),
                    dropped_points=sum(int(dict(scans[k].metadata).get("dropped_nonfinite_points", 0)) for k in g))
            for g in groups]

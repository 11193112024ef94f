"""Helpers shared by the scan readers and writers."""
from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np

from common.errors import ScanFormatError
from common.files import atomic_output  # noqa: F401  (used by every writer)
from lidar.io.intensity import detect_convention
from lidar.scan import Scan, normalise_intensity


def first_line(exc: BaseException) -> str:
    """First non-empty line of an exception's message (libraries often add dumps after it)."""
    for line in str(exc).splitlines():
        if line.strip():
            return line.strip()
    return type(exc).__name__


def check_readable(path: str | os.PathLike) -> Path:
    """Raise ScanFormatError unless ``path`` is an existing, non-empty file."""
    p = Path(path)
    if not p.exists():
        raise ScanFormatError(p, "no such file; check the path")
    if not p.is_file():
        raise ScanFormatError(p, "is not a file")
    if p.stat().st_size == 0:
        raise ScanFormatError(p, "the file is empty (0 bytes)")
    return p


def make_scan(
    path: Path,
    xyz: np.ndarray,
    raw: np.ndarray | None,
    *,
    fmt: str,
    limits: tuple[float, float] | None = None,
    pose: np.ndarray | None = None,
    name: str = "",
    grid_index: np.ndarray | None = None,
    metadata: dict | None = None,
    finite: bool = False,
    time_s: np.ndarray | None = None,
) -> Scan:
    """Build a Scan from decoded arrays: drop non-finite points, normalise intensity.

    ``finite=True`` tells that the values cannot be NaN/inf (integer formats)
    and skips that check. ``limits`` is an intensity range the file declares;
    without one the vendor convention is recognised from the values
    (:mod:`lidar.io.intensity`). Raises ScanFormatError when nothing valid is
    left or the header's pose is not a finite rigid transform. ``time_s`` (N,) point times, seconds,
    are kept with their points.
    """
    meta = {"format": fmt, **(metadata or {})}
    xyz = np.asarray(xyz, dtype=np.float64)
    if raw is not None:
        raw = np.asarray(raw)
    dropped = 0
    if not finite:
        ok = np.isfinite(xyz).all(axis=1)
        if raw is not None and raw.dtype.kind == "f":
            ok &= np.isfinite(raw)
        dropped = int(ok.size - np.count_nonzero(ok))
    if dropped:
        xyz = xyz[ok]
        raw = raw[ok] if raw is not None else None
        grid_index = grid_index[ok] if grid_index is not None else None
        time_s = time_s[ok] if time_s is not None else None
        meta["dropped_nonfinite_points"] = dropped
    if xyz.shape[0] == 0:
        raise ScanFormatError(path, "holds no valid points" + (f" ({dropped} were NaN/inf)" if dropped else ""))
    intensity = None
    if raw is not None:
        convention, limits = detect_convention(raw, declared=limits)
        if limits is None:
            limits = (float(raw.min()), float(raw.max()))
        meta["intensity_convention"] = convention
        meta["intensity_limits"] = (float(limits[0]), float(limits[1]))
        intensity = normalise_intensity(raw, limits)
    if pose is not None:
        pose = np.asarray(pose, dtype=np.float64)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ScanFormatError(path, "the scanner pose in the header is not a finite 4x4 transform")
        rot = pose[:3, :3]
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-5) or not np.allclose(pose[3], (0, 0, 0, 1), atol=1e-9):
            raise ScanFormatError(path, "the scanner pose in the header is not a rigid transform "
                                        "(its rotation is not orthonormal)")
    return Scan(
        xyz_socs=np.ascontiguousarray(xyz),
        intensity=intensity,
        intensity_raw=raw,
        pose=pose,
        source=str(path),
        name=name or path.stem,
        grid_index=grid_index,
        metadata=meta,
        time_s=time_s,
    )


def pose_to_text(pose: np.ndarray) -> str:
    """A 4x4 pose as 16 numbers, row by row (the header line PLY and XYZ files carry it in)."""
    return " ".join(f"{v:.15g}" for v in np.asarray(pose, dtype=np.float64).ravel())


def pose_from_text(path: Path, words: list[str], what: str) -> np.ndarray:
    """The 4x4 pose written by :func:`pose_to_text`; ScanFormatError naming ``what`` unless 16 numbers."""
    try:
        vals = np.array([float(v) for v in words])
    except ValueError as exc:
        raise ScanFormatError(path, f"the {what} is not 16 numbers") from exc
    if vals.size != 16:
        raise ScanFormatError(path, f"the {what} is not 16 numbers")
    return vals.reshape(4, 4)


def read_ascii_table(path: Path, fh: BinaryIO, *, sep: str, nrows: int | None, what: str,
                     ncols: int | None = None) -> np.ndarray:
    r"""Parse ASCII point lines from an open binary file at its current position (pandas' C reader).

    ``sep`` is a separator or ``r"\\s+"``; ``ncols`` fixes the number of columns (longer lines are
    an error); ``what`` names the lines in the ScanFormatError for a malformed one.
    """
    # local: pandas costs every command that reads scans 0.15-0.2 s of start-up (measured)
    import pandas as pd

    try:
        return pd.read_csv(fh, sep=sep, header=None, dtype=np.float64, engine="c", skip_blank_lines=True,
                           on_bad_lines="error", nrows=nrows,
                           **({} if ncols is None else {"names": range(ncols), "comment": None})).to_numpy()
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ScanFormatError(path, f"malformed {what} ({msg[:100]})") from exc


def pose_from_quaternion(q_wxyz: Sequence[float], t: Sequence[float]) -> np.ndarray:
    """4x4 homogeneous transform from a unit quaternion (w, x, y, z) and a translation."""
    w, x, y, z = (float(v) for v in q_wxyz)
    n = np.sqrt(w * w + x * x + y * y + z * z)
    if n == 0:
        w, n = 1.0, 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    pose = np.eye(4)
    pose[:3, :3] = r
    pose[:3, 3] = np.asarray(t, dtype=np.float64)
    return pose


def quaternion_from_pose(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w, x, y, z) unit quaternion and translation of a rigid 4x4 transform."""
    # local: scipy.spatial costs 'info' and the other file commands 0.3-0.4 s of start-up (measured)
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(pose[:3, :3]).as_quat()
    return np.array([w, x, y, z]), np.asarray(pose[:3, 3], dtype=np.float64)


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Silence C/C++ libraries that print diagnostics straight to file descriptor 2."""
    try:
        fd = os.dup(2)
    except OSError:  # pragma: no cover - no stderr at all
        yield
        return
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 2)
            yield
    finally:
        os.dup2(fd, 2)
        os.close(fd)


def raw_for_writing(scan: Scan) -> np.ndarray:
    """Intensity values to store: the raw ones if present, else normalised scaled to uint16."""
    if scan.intensity_raw is not None:
        return scan.intensity_raw
    if scan.intensity is not None:
        return np.round(scan.intensity.astype(np.float64) * 65535).astype(np.uint16)
    return np.zeros(len(scan), np.uint16)

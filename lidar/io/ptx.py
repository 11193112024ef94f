"""PTX (Leica ASCII grid) files: one or several scans, each with its header pose and grid."""
from __future__ import annotations

import itertools
import os
from pathlib import Path

import numpy as np

from common.errors import ScanFormatError
from lidar.io._common import atomic_output, check_readable, first_line, make_scan, raw_for_writing
from lidar.scan import Scan

#: Point lines parsed at a time (memory: the decoded arrays plus one chunk of text).
CHUNK_LINES = 262_144


def read_ptx(path: str | os.PathLike) -> list[Scan]:
    """Read every scan of a PTX file.

    Each scan's header holds the column and row counts, the scanner position and
    axes, and a 4x4 transform (stored transposed, translation in the last row);
    that transform becomes the scan's pose. Points are in the scanner's frame.
    Grid cells without a return ((0, 0, 0)) are dropped; each kept point keeps
    its (row, col) grid index. Point lines are ``x y z intensity`` with
    optional ``r g b``; the rows x columns a header claims are checked against
    the bytes left before any array is made.
    """
    p = check_readable(path)
    size = p.stat().st_size
    scans: list[Scan] = []
    with open(p, "rb") as fh:
        while True:
            head: list[str] = []
            while len(head) < 10:
                raw = fh.readline(4096)
                if not raw:
                    break
                if b"\0" in raw:
                    raise ScanFormatError(p, "not a PTX file (binary content)")
                if raw.strip() or head:
                    head.append(raw.decode("ascii", "replace"))
            if not head:
                break
            k = len(scans)
            try:
                cols = int(head[0].split()[0])
                rows = int(head[1].split()[0])
                mat = np.array([[float(v) for v in ln.split()[:4]] for ln in head[6:10]], dtype=np.float64)
                if cols <= 0 or rows <= 0 or mat.shape != (4, 4):
                    raise ValueError("bad header")
            except (ValueError, IndexError) as exc:
                raise ScanFormatError(p, f"not a PTX file or a malformed header of scan {k}") from exc
            n = rows * cols
            left = size - fh.tell()
            if n * 6 > left + 1:  # "0 0 0\n" is the shortest point line
                raise ScanFormatError(p, f"truncated or lying PTX header: scan {k} declares {rows} x {cols} = {n} "
                                         f"points, the file has room for at most {(left + 1) // 6}")
            table = _read_points(p, fh, n, k)
            xyz = table[:, :3]
            raw_i = table[:, 3] if table.shape[1] >= 4 else None
            # PTX is written column by column: point j is at column j // rows, row j % rows.
            j = np.arange(n)
            grid = np.column_stack([j % rows, j // rows]).astype(np.int32)
            valid = np.any(xyz != 0.0, axis=1)
            scans.append(
                make_scan(p, xyz[valid], raw_i[valid] if raw_i is not None else None, fmt="PTX",
                          pose=mat.T, name=f"{p.stem}#{k}", grid_index=grid[valid],
                          metadata={"scan_index": k, "rows": rows, "cols": cols})
            )
    if not scans:
        raise ScanFormatError(p, "the PTX file holds no scans")
    return scans


def _read_points(p: Path, fh, n: int, k: int) -> np.ndarray:
    """Parse the ``n`` point lines of scan ``k`` chunk by chunk into one array."""
    table = None
    done = 0
    while done < n:
        lines = list(itertools.islice(fh, min(CHUNK_LINES, n - done)))
        if len(lines) < min(CHUNK_LINES, n - done):
            raise ScanFormatError(p, f"truncated: scan {k} declares {n} points but the file holds {done + len(lines)}")
        try:
            chunk = np.loadtxt(lines, dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise ScanFormatError(p, f"corrupt point line in scan {k} ({first_line(exc)[:80]})") from exc
        if table is None:
            if chunk.shape[1] < 3:
                raise ScanFormatError(p, f"scan {k}: point lines need at least x y z")
            table = np.empty((n, min(chunk.shape[1], 4)), dtype=np.float64)
        if chunk.shape[1] < table.shape[1]:
            raise ScanFormatError(p, f"scan {k}: point lines change their number of values")
        table[done:done + len(chunk)] = chunk[:, :table.shape[1]]
        done += len(chunk)
    if table is None:
        raise ScanFormatError(p, f"scan {k} holds no points")
    return table


def write_ptx(scan: Scan, path: str | os.PathLike) -> Path:
    """Write a scan as a single-column PTX grid (rows = points) with its pose."""
    final = Path(path)
    pose = scan.pose if scan.pose is not None else np.eye(4)
    raw = scan.intensity if scan.intensity is not None else raw_for_writing(scan).astype(np.float64)
    n = len(scan)
    head = ["1", f"{n}", " ".join(f"{v:.10g}" for v in pose[:3, 3])]
    head += [" ".join(f"{v:.10g}" for v in pose[:3, k]) for k in range(3)]
    head += [" ".join(f"{v:.12g}" for v in row) for row in pose.T]
    table = np.column_stack([scan.xyz_socs, raw])
    with atomic_output(final) as tmp:
        with open(tmp, "w", encoding="ascii") as fh:
            fh.write("\n".join(head) + "\n")
            np.savetxt(fh, table, fmt="%.6f %.6f %.6f %.6f")
    return final

"""PTX (Leica ASCII grid) files: one or several scans, each with its header pose and grid."""
from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from lidar.errors import ScanFormatError
from lidar.io._common import atomic_output, check_readable, make_scan, raw_for_writing
from lidar.scan import Scan


def read_ptx(path: str | os.PathLike) -> list[Scan]:
    """Read every scan of a PTX file.

    Each scan's header holds the column and row counts, the scanner position and
    axes, and a 4x4 transform (stored transposed, translation in the last row);
    that transform becomes the scan's pose. Points are in the scanner's frame.
    Grid cells without a return ((0, 0, 0)) are dropped; each kept point keeps
    its (row, col) grid index.
    """
    p = check_readable(path)
    try:
        lines = p.read_text(encoding="ascii", errors="strict").splitlines()
    except UnicodeDecodeError as exc:
        raise ScanFormatError(p, "not a PTX file (binary content)") from exc
    scans: list[Scan] = []
    pos = 0
    while pos < len(lines):
        if not lines[pos].strip():
            pos += 1
            continue
        try:
            cols = int(lines[pos].split()[0])
            rows = int(lines[pos + 1].split()[0])
            mat = np.loadtxt(lines[pos + 6:pos + 10], dtype=np.float64, ndmin=2)
            if cols <= 0 or rows <= 0 or mat.shape != (4, 4):
                raise ValueError("bad header")
        except (ValueError, IndexError) as exc:
            raise ScanFormatError(p, f"not a PTX file or a malformed scan header at line {pos + 1}") from exc
        n = rows * cols
        start = pos + 10
        body = lines[start:start + n]
        if len(body) < n:
            raise ScanFormatError(p, f"truncated: scan {len(scans)} declares {n} points but the file holds {len(body)}")
        try:
            table = np.loadtxt(io.StringIO("\n".join(body)), dtype=np.float64, ndmin=2)
        except ValueError as exc:
            raise ScanFormatError(p, f"corrupt point line in scan {len(scans)} ({exc})") from exc
        if table.shape[1] < 3:
            raise ScanFormatError(p, f"scan {len(scans)}: point lines need at least x y z")
        xyz = table[:, :3]
        raw = table[:, 3] if table.shape[1] >= 4 else None
        # PTX is written column by column: point k is at column k // rows, row k % rows.
        k = np.arange(n)
        grid = np.column_stack([k % rows, k // rows]).astype(np.int32)
        valid = np.any(xyz != 0.0, axis=1)
        pose = mat.T
        scans.append(
            make_scan(p, xyz[valid], raw[valid] if raw is not None else None, fmt="PTX",
                      pose=pose, name=f"{p.stem}#{len(scans)}", grid_index=grid[valid],
                      metadata={"scan_index": len(scans), "rows": rows, "cols": cols})
        )
        pos = start + n
    if not scans:
        raise ScanFormatError(p, "the PTX file holds no scans")
    return scans


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

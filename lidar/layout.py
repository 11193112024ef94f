"""The campaign's reflector layout: ids, groups and approximate coordinates (any frame)."""
from __future__ import annotations

import csv
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError

if TYPE_CHECKING:
    from lidar.simulate.bridge import BridgeModel

GROUPS = ("reference", "measurement")
REQUIRED_COLUMNS = ("id", "group", "x", "y", "z")
NORMAL_COLUMNS = ("nx", "ny", "nz")


@dataclass(frozen=True, eq=False)
class Layout:
    """Reflector layout.

    Attributes
    ----------
    ids : tuple of str
    groups : tuple of {"reference", "measurement"}
    xyz : (N, 3) float64 array
        Approximate coordinates (a few cm) in any frame (design drawings, a total station...).
    diameters_m : (N,) float64 array
    normals : (N, 3) float64 array, optional
        Unit normal of each target (pointing away from the surface it is glued to), in the
        layout's frame; NaN rows where the layout gives none (see :func:`target_normals`).
    """

    ids: tuple[str, ...]
    groups: tuple[str, ...]
    xyz: np.ndarray
    diameters_m: np.ndarray
    normals: np.ndarray = None  # type: ignore[assignment]  # None: __post_init__ fills NaN rows

    def __post_init__(self) -> None:
        n = len(self.ids)
        xyz = np.asarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        if xyz.shape[0] != n or len(self.groups) != n or np.shape(self.diameters_m) != (n,):
            raise InputError("layout: ids, groups, coordinates and diameters must have the same length")
        if len(set(self.ids)) != n:
            dup = sorted({i for i in self.ids if self.ids.count(i) > 1})
            raise InputError(f"layout: duplicate reflector ids {dup}")
        bad = [g for g in self.groups if g not in GROUPS]
        if bad:
            raise InputError(f"layout: group must be 'reference' or 'measurement', got {bad[0]!r}")
        if not np.all(np.isfinite(xyz)):
            raise InputError("layout: coordinates must be finite numbers")
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "diameters_m", np.asarray(self.diameters_m, dtype=np.float64))
        normals = np.full((n, 3), np.nan) if self.normals is None else \
            np.asarray(self.normals, dtype=np.float64).reshape(-1, 3)
        if normals.shape != (n, 3):
            raise InputError("layout: one normal (or none) per reflector")
        given = np.all(np.isfinite(normals), axis=1)
        length = np.linalg.norm(normals[given], axis=1)
        if np.any(length < 1e-9):
            raise InputError("layout: a target normal must not be zero")
        normals[given] = normals[given] / length[:, None]
        object.__setattr__(self, "normals", normals)

    def __len__(self) -> int:
        return len(self.ids)

    def index(self, reflector_id: str) -> int:
        try:
            return self.ids.index(reflector_id)
        except ValueError:
            raise InputError(f"unknown reflector {reflector_id!r}; the layout has {', '.join(self.ids)}") from None

    def group_of(self, reflector_id: str) -> str:
        return self.groups[self.index(reflector_id)]

    def ids_in(self, group: str) -> tuple[str, ...]:
        return tuple(i for i, g in zip(self.ids, self.groups, strict=False) if g == group)

    def subset(self, ids: Sequence[str]) -> Layout:
        idx = [self.index(i) for i in ids]
        return Layout(tuple(self.ids[k] for k in idx), tuple(self.groups[k] for k in idx), self.xyz[idx],
                      self.diameters_m[idx], self.normals[idx])

    def to_rows(self) -> list[dict]:
        rows = []
        for i, g, p, d, nrm in zip(self.ids, self.groups, self.xyz, self.diameters_m, self.normals, strict=False):
            row = {"id": i, "group": g, "x": float(p[0]), "y": float(p[1]), "z": float(p[2]),
                   "diameter_mm": float(d * 1000)}
            if np.all(np.isfinite(nrm)):
                row.update(nx=float(nrm[0]), ny=float(nrm[1]), nz=float(nrm[2]))
            rows.append(row)
        return rows


def read_layout_csv(path: str | os.PathLike, *, default_diameter_m: float = 0.05) -> Layout:
    """Read ``layout.csv``: columns ``id,group,x,y,z``, optionally ``diameter_mm`` and ``nx,ny,nz``.

    Raises
    ------
    InputError
        Naming the file, the line and the problem (missing column, bad group,
        non-numeric or NaN coordinate, duplicate id, too few reflectors).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: layout file not found")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (UnicodeDecodeError, OSError) as exc:
        raise InputError(f"{p}: cannot read the layout as text ({exc})") from exc
    reader = csv.DictReader(text.splitlines())
    fields = [f.strip().lower() for f in (reader.fieldnames or [])]
    missing = [c for c in REQUIRED_COLUMNS if c not in fields]
    if missing:
        raise InputError(f"{p}: layout is missing column(s) {', '.join(missing)}; expected id,group,x,y,z[,diameter_mm]")
    has_normals = all(c in fields for c in NORMAL_COLUMNS)
    if any(c in fields for c in NORMAL_COLUMNS) and not has_normals:
        raise InputError(f"{p}: target normals need all three columns nx,ny,nz")
    ids, groups, xyz, diam, normals = [], [], [], [], []
    for line_no, row in enumerate(reader, start=2):
        row = {(k or "").strip().lower(): (v or "").strip() for k, v in row.items()}
        if not any(row.values()):
            continue
        rid, group = row["id"], row["group"].lower()
        if not rid:
            raise InputError(f"{p}, line {line_no}: empty reflector id")
        if group not in GROUPS:
            raise InputError(f"{p}, line {line_no}: group must be 'reference' or 'measurement', got {row['group']!r}")
        try:
            coords = [float(row[c]) for c in ("x", "y", "z")]
            d = float(row["diameter_mm"]) / 1000 if row.get("diameter_mm") else default_diameter_m
        except ValueError:
            raise InputError(f"{p}, line {line_no}: coordinates and diameter must be numbers") from None
        if not np.all(np.isfinite(coords)) or not np.isfinite(d) or d <= 0:
            raise InputError(f"{p}, line {line_no}: coordinates must be finite and the diameter positive")
        if rid in ids:
            raise InputError(f"{p}, line {line_no}: duplicate reflector id {rid!r}")
        normals.append(_normal_of_row(row, has_normals, f"{p}, line {line_no}"))
        ids.append(rid)
        groups.append(group)
        xyz.append(coords)
        diam.append(d)
    layout = Layout(tuple(ids), tuple(groups), np.array(xyz, dtype=np.float64).reshape(-1, 3), np.array(diam),
                    np.array(normals, dtype=np.float64).reshape(-1, 3))
    check_layout(layout, source=str(p))
    return layout


def _normal_of_row(row: dict, has_normals: bool, where: str) -> list[float]:
    """The row's normal, or NaNs when the layout has none (an empty cell means unknown)."""
    if not has_normals or not any(row.get(c) for c in NORMAL_COLUMNS):
        return [float("nan")] * 3
    try:
        n = [float(row[c]) for c in NORMAL_COLUMNS]
    except ValueError:
        raise InputError(f"{where}: nx,ny,nz must be numbers (or all three empty)") from None
    if not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
        raise InputError(f"{where}: the target normal nx,ny,nz must be finite and not zero")
    return n


def check_layout(layout: Layout, *, source: str = "layout") -> None:
    """A usable layout has at least 2 reference and 3 measurement reflectors."""
    n_ref = len(layout.ids_in("reference"))
    n_meas = len(layout.ids_in("measurement"))
    if n_ref < 2:
        raise InputError(f"{source}: needs at least 2 reference reflectors (found {n_ref})")
    if n_meas < 3:
        raise InputError(f"{source}: needs at least 3 measurement reflectors to define the deck plane (found {n_meas})")


def write_layout_csv(layout: Layout, path: str | os.PathLike) -> Path:
    """Write a layout as ``layout.csv`` (id,group,x,y,z,diameter_m[,nx,ny,nz]) atomically; returns the path."""
    p = Path(path)
    with open(p, "w", newline="", encoding="utf-8") as fh:
        fields = ["id", "group", "x", "y", "z", "diameter_mm"]
        if np.any(np.all(np.isfinite(layout.normals), axis=1)):
            fields += list(NORMAL_COLUMNS)
        w = csv.DictWriter(fh, fieldnames=fields, restval="")
        w.writeheader()
        for row in layout.to_rows():
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in row.items()})
    return p


def layout_from_model(model: BridgeModel, *, noise_m: float = 0.0, rng: np.random.Generator | None = None,
                      with_normals: bool = False) -> Layout:
    """The layout of a simulated bridge, optionally with design-drawing-like errors and the targets' normals."""
    rng = rng or np.random.default_rng(0)
    xyz = np.array([t.centre_m for t in model.targets]) + rng.normal(0, noise_m, (len(model.targets), 3))
    return Layout(tuple(t.id for t in model.targets), tuple(t.group for t in model.targets), xyz,
                  np.array([t.diameter_m for t in model.targets]),
                  np.array([t.normal for t in model.targets]) if with_normals else None)  # type: ignore[arg-type]


def bridge_axis(layout: Layout, *, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Unit horizontal direction along the bridge in the layout's frame (its sign is arbitrary).

    The principal axis of every target's position projected on the horizontal plane: the targets
    spread along the span far more than across it.
    """
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    p = layout.xyz - layout.xyz.mean(axis=0)
    p = p - np.outer(p @ u, u)
    _, _, vt = np.linalg.svd(p, full_matrices=False)
    a = vt[0] - (vt[0] @ u) * u
    return a / np.linalg.norm(a)


#: Reference targets closer than this along the bridge (m) are on one pier.
PIER_GAP_M = 4.0


def _reference_facing(ref_along: np.ndarray, deck_along: np.ndarray) -> np.ndarray:
    """+1 or -1 per reference target: which way along the bridge axis its pier face looks.

    Reference targets are grouped by pier (along-axis gaps over :data:`PIER_GAP_M`). An end pier (deck
    targets on one side only) has its targets facing the deck; on an inner pier each target faces the
    span on its own side of the pier (the pier's middle between its targets, or, for a lone target, the
    nearer of the deck targets on either side).
    """
    out = np.ones(len(ref_along))
    if not len(ref_along):
        return out
    order = np.argsort(ref_along)
    groups, cur = [], [order[0]]
    for a, b in zip(order[:-1], order[1:], strict=False):
        if ref_along[b] - ref_along[a] > PIER_GAP_M:
            groups.append(cur)
            cur = []
        cur.append(b)
    groups.append(cur)
    for g in groups:
        centre = float(np.mean(ref_along[g]))
        left = deck_along[deck_along < centre - 1.0]
        right = deck_along[deck_along > centre + 1.0]
        for k in g:
            if not left.size or not right.size:  # an end pier: its face looks into the span
                out[k] = 1.0 if right.size else -1.0
            elif len(g) > 1 and abs(ref_along[k] - centre) > 0.25:
                out[k] = -1.0 if ref_along[k] < centre else 1.0
            else:
                out[k] = -1.0 if centre - left.max() < right.min() - centre else 1.0
    return out


def target_normals(layout: Layout, *, up: ArrayLike = (0.0, 0.0, 1.0)) -> np.ndarray:
    """(N, 3) unit normal of every target in the layout's frame.

    The layout's own normals (``nx,ny,nz``) where given. Otherwise a measurement target faces
    down (glued under the deck) and a reference target faces along the bridge axis, toward the
    span (glued on the pier face looking into it; on an inner pier, the span on its own side, see
    :func:`_reference_facing`).
    """
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    out = layout.normals.copy()
    missing = ~np.all(np.isfinite(out), axis=1)
    if not np.any(missing):
        return out
    axis = bridge_axis(layout, up=u)
    meas = np.array([g == "measurement" for g in layout.groups])
    deck_along = layout.xyz[meas] @ axis if np.any(meas) else layout.xyz @ axis
    refs = [k for k in range(len(layout.ids)) if layout.groups[k] != "measurement"]
    facing = _reference_facing(layout.xyz[refs] @ axis, deck_along)
    for k in np.nonzero(missing)[0]:
        out[k] = -u if layout.groups[k] == "measurement" else axis * facing[refs.index(int(k))]
    return out

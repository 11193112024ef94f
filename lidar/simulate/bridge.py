"""A bridge of one or several spans with retro-reflective targets, as triangle meshes for ray casting.

Bridge frame: x along the span (pier 1 at x = 0, the last pier at x = the
sum of the spans), z up, ground at z = 0, the access side (where the scanner
usually stands) at y < 0.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import ArrayLike

from common.errors import InputError


@dataclass(frozen=True)
class Target:
    """A retro-reflective disc glued to the structure.

    Attributes
    ----------
    id : str
    group : {"reference", "measurement"}
    centre_m : (3,) float tuple
        Centre of the disc in the bridge frame, undeformed, metres.
    normal : (3,) float tuple
        Outward unit normal of the surface it is glued to.
    diameter_m : float
    """

    id: str
    group: str
    centre_m: tuple[float, ...]
    normal: tuple[float, ...]
    diameter_m: float = 0.05

    def __post_init__(self) -> None:
        if self.group not in ("reference", "measurement"):
            raise InputError(f"target {self.id}: group must be 'reference' or 'measurement', not {self.group!r}")
        n = np.asarray(self.normal, dtype=float)
        object.__setattr__(self, "normal", tuple(float(v) for v in n / np.linalg.norm(n)))
        object.__setattr__(self, "centre_m", tuple(float(v) for v in self.centre_m))


def _default_targets(span: float, pier_length: float, deck_bottom: float, diameter: float) -> tuple[Target, ...]:
    """The demo bridge's nine targets.

    Four reference targets on the piers' inner faces (looking into the span, where a scanner between the piers sees
    them at moderate incidence), at two heights and two positions across the
    bridge; five measurement targets under the deck, symmetric about midspan, on two girder lines.
    """
    face1 = pier_length / 2 + 0.001  # pier 1's +x face, 1 mm proud
    face2 = span - pier_length / 2 - 0.001  # pier 2's -x face
    ref = [
        Target("R1", "reference", (face1, -1.5, 2.0), (1, 0, 0), diameter),
        Target("R2", "reference", (face1, 1.5, 5.0), (1, 0, 0), diameter),
        Target("R3", "reference", (face2, 1.5, 2.0), (-1, 0, 0), diameter),
        Target("R4", "reference", (face2, -1.5, 5.0), (-1, 0, 0), diameter),
    ]
    z = deck_bottom - 0.001
    fractions = (0.2, 0.35, 0.5, 0.65, 0.8)
    ys = (-2.0, 1.0, -2.0, 1.0, -2.0)
    meas = [Target(f"M{k + 1}", "measurement", (f * span, y, z), (0, 0, -1), diameter)
            for k, (f, y) in enumerate(zip(fractions, ys, strict=False))]
    return tuple(ref + meas)


#: Deck target positions along each span (fractions of it) and girder lines of a multi-span layout by default.
DEFAULT_DECK_FRACTIONS = (0.4, 0.5, 0.6)


def _layout_targets(model: BridgeModel) -> tuple[Target, ...]:
    """A multi-span layout (also used for one span when deck fractions or girder lines are given).

    Reference targets R1, R2 on the first pier's +x face (low on the access side, high on the far side), then
    for each inner pier one on its -x face (high, far side) and one on its +x face (low, access side), then two on
    the last pier's -x face (low far side, high access side): R1..R(2 n_spans + 2) in order along x. Deck
    (measurement) targets M1.. span by span, in each span girder line by girder line, along x within a line.
    """
    d = model.target_diameter_m
    proud = model.pier_length_m / 2 + 0.001  # a pier face, 1 mm proud
    y_off = 0.3 * model.pier_width_m
    z_lo, z_hi = model.deck_bottom_m * 2.0 / 7.0, model.deck_bottom_m * 5.0 / 7.0
    xs = model.support_x_m
    ref = [((proud, -y_off, z_lo), (1, 0, 0)), ((proud, y_off, z_hi), (1, 0, 0))]
    for x in xs[1:-1]:
        ref += [((x - proud, y_off, z_hi), (-1, 0, 0)), ((x + proud, -y_off, z_lo), (1, 0, 0))]
    ref += [((xs[-1] - proud, y_off, z_lo), (-1, 0, 0)), ((xs[-1] - proud, -y_off, z_hi), (-1, 0, 0))]
    out = [Target(f"R{k + 1}", "reference", c, n, d) for k, (c, n) in enumerate(ref)]
    fractions = model.deck_fractions or DEFAULT_DECK_FRACTIONS
    lines = model.girder_lines_m or (-model.deck_width_m / 4, model.deck_width_m / 4)
    z = model.deck_bottom_m - 0.001
    k = 0
    for x0, span in zip(xs[:-1], model.spans_m, strict=False):
        for y in lines:
            for f in fractions:
                k += 1
                out.append(Target(f"M{k}", "measurement", (x0 + f * span, y, z), (0, 0, -1), d))
    return tuple(out)


def _continuous_beam(spans: Sequence[float], loads: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Vertical displacement (up, EI = 1) of a continuous beam on simple supports under a uniform load per span.

    ``loads`` (n_spans,) downward; support moments from the three-moment equation (zero at the end supports),
    then within each span the simple-span sag under its load plus the effect of its two support moments.
    """
    n = len(spans)
    lengths = np.asarray(spans, dtype=np.float64)
    moments = np.zeros(n + 1)
    if n > 1:
        a = np.zeros((n - 1, n - 1))
        b = np.zeros(n - 1)
        for j in range(1, n):
            left, right = lengths[j - 1], lengths[j]
            a[j - 1, j - 1] = 2.0 * (left + right)
            if j > 1:
                a[j - 1, j - 2] = left
            if j < n - 1:
                a[j - 1, j] = right
            b[j - 1] = -(loads[j - 1] * left ** 3 + loads[j] * right ** 3) / 4.0
        moments[1:n] = np.linalg.solve(a, b)
    starts = np.concatenate([[0.0], np.cumsum(lengths)])
    out = np.zeros(x.shape)
    for k in range(n):
        sel = (x >= starts[k]) & (x <= starts[k + 1])
        L = lengths[k]
        xi = (x[sel] - starts[k]) / L
        sag = -loads[k] * L ** 4 * (xi - 2 * xi ** 3 + xi ** 4) / 24.0
        ends = -(L ** 2 / 6.0) * (moments[k] * (2 * xi - 3 * xi ** 2 + xi ** 3) + moments[k + 1] * (xi - xi ** 3))
        out[sel] = sag + ends
    return out


def continuous_deflection(spans_m: Sequence[float], amplitudes_m: ArrayLike, x_m: ArrayLike) -> np.ndarray:
    """Deflection of a continuous beam whose midspans move by ``amplitudes_m`` (m, positive up).

    The uniform loads per span that give exactly these midspan displacements are solved for (each span's load
    also bends its neighbours, through the moments over the inner piers), so the line is smooth over the inner
    piers, unlike a half-sine per span; zero at every support and outside the bridge.

    Parameters
    ----------
    spans_m : (n,) span lengths, metres.
    amplitudes_m : (n,) vertical displacement at each midspan, metres, positive up.
    x_m : array of positions along the bridge from the first pier, metres.

    Returns
    -------
    Array shaped like ``x_m``, metres.
    """
    x = np.asarray(x_m, dtype=np.float64)
    n = len(spans_m)
    mids = np.cumsum(spans_m) - np.asarray(spans_m, dtype=np.float64) / 2
    response = np.column_stack([_continuous_beam(spans_m, np.eye(n)[j], mids) for j in range(n)])
    loads = np.linalg.solve(response, np.asarray(amplitudes_m, dtype=np.float64))
    flat = x.reshape(-1)
    return _continuous_beam(spans_m, loads, flat).reshape(x.shape)


@dataclass(frozen=True)
class BridgeModel:
    """Geometry of the simulated bridge (metres).

    A box-girder deck, continuous over the inner piers, overhanging the end piers by
    ``overhang_m``, on rectangular piers at every support, above flat ground.

    Attributes
    ----------
    span_m : float
        Distance between the end piers' centrelines. Default 40 m, one span. When ``spans_m`` is
        given it follows them (their sum).
    deck_width_m, deck_bottom_m, deck_depth_m, overhang_m : float
        Deck section (width, height of its underside above ground, depth) and overhang past the end piers.
    pier_length_m, pier_width_m : float
        Pier box along x and across.
    target_diameter_m : float
    targets : tuple of Target
        Default (empty): the default layout. One span without ``deck_fractions`` and ``girder_lines_m``: the
        demo's nine targets (R1, R2 on pier 1's inner face, R3, R4 on pier 2's, M1..M5 under the deck at
        0.2..0.8 of the span on alternating girder lines). Otherwise the multi-span layout: two targets on each
        end pier's inner face, one on each face of every inner pier, ids R1..R(2n+2) in order along x; deck
        targets M1.. at ``deck_fractions`` of every span on every girder line, span by span, line by line.
    spans_m : tuple of float
        Span lengths between consecutive supports, e.g. ``(39.9, 39.9, 39.9)``. Default (empty): ``(span_m,)``.
    deck_fractions : tuple of float
        Deck target positions along each span, fractions in (0, 1). Default (empty): (0.4, 0.5, 0.6).
    girder_lines_m : tuple of float
        Transverse positions (y) of the deck target lines. Default (empty): +-deck width / 4.
    deflection_shape : {"sine", "continuous"}
        "sine": a half-sine in each span with its own amplitude. "continuous": a continuous beam whose
        midspans move by the amplitudes (adjoining spans interact). Both are zero at every support.
    """

    span_m: float = 40.0
    deck_width_m: float = 6.0
    deck_bottom_m: float = 7.0
    deck_depth_m: float = 2.0
    overhang_m: float = 1.0
    pier_length_m: float = 2.0
    pier_width_m: float = 5.0
    target_diameter_m: float = 0.05
    targets: tuple[Target, ...] = field(default=())
    spans_m: tuple[float, ...] = ()
    deck_fractions: tuple[float, ...] = ()
    girder_lines_m: tuple[float, ...] = ()
    deflection_shape: str = "sine"

    def __post_init__(self) -> None:
        spans = tuple(float(v) for v in self.spans_m) or (float(self.span_m),)
        if not all(np.isfinite(spans)) or min(spans) <= 0 or self.deck_width_m <= 0 or self.deck_bottom_m <= 0:
            raise InputError("bridge model dimensions must be positive")
        object.__setattr__(self, "spans_m", spans)
        object.__setattr__(self, "span_m", float(sum(spans)) if len(spans) > 1 else spans[0])
        object.__setattr__(self, "deck_fractions", tuple(float(f) for f in self.deck_fractions))
        object.__setattr__(self, "girder_lines_m", tuple(float(y) for y in self.girder_lines_m))
        if any(not 0.0 < f < 1.0 for f in self.deck_fractions):
            raise InputError(f"bridge model: deck target fractions must lie in (0, 1), got {self.deck_fractions}")
        if any(abs(y) >= self.deck_width_m / 2 for y in self.girder_lines_m):
            raise InputError(f"bridge model: girder lines {self.girder_lines_m} must lie under the deck "
                             f"(|y| < {self.deck_width_m / 2:g} m)")
        if self.deflection_shape not in ("sine", "continuous"):
            raise InputError(f"bridge model: deflection_shape must be 'sine' or 'continuous', "
                             f"not {self.deflection_shape!r}")
        if not self.targets:
            legacy = len(spans) == 1 and not self.deck_fractions and not self.girder_lines_m
            object.__setattr__(self, "targets", _default_targets(
                self.span_m, self.pier_length_m, self.deck_bottom_m, self.target_diameter_m) if legacy
                else _layout_targets(self))
        ids = [t.id for t in self.targets]
        if len(set(ids)) != len(ids):
            raise InputError("bridge model: target ids must be unique")

    @property
    def n_spans(self) -> int:
        return len(self.spans_m)

    @property
    def support_x_m(self) -> tuple[float, ...]:
        """Position along x of every support (pier centreline), from 0 to the bridge's length, metres."""
        return tuple(float(v) for v in np.concatenate([[0.0], np.cumsum(self.spans_m)]))

    @property
    def length_m(self) -> float:
        """Distance between the end piers' centrelines, metres."""
        return self.support_x_m[-1]

    def target(self, target_id: str) -> Target:
        for t in self.targets:
            if t.id == target_id:
                return t
        raise InputError(f"bridge model has no target {target_id!r}")

    def deflection_m(self, x_m: ArrayLike, midspan_m: float | Sequence[float]) -> np.ndarray:
        """Vertical displacement (positive up) along the bridge for midspan amplitudes.

        Parameters
        ----------
        x_m : array of positions along the bridge from the first pier, metres.
        midspan_m : float or (n_spans,) sequence
            Displacement at midspan, metres: one value for every span, or one per span.

        Returns
        -------
        Array shaped like ``x_m``: the model's ``deflection_shape`` (a half-sine ``a sin(pi x / L)`` per
        span by default), zero at every support and outside the end supports.
        """
        x = np.asarray(x_m, dtype=np.float64)
        if self.n_spans == 1 and self.deflection_shape == "sine" and np.ndim(midspan_m) == 0:
            w = float(midspan_m) * np.sin(np.pi * x / self.span_m)  # type: ignore[arg-type]
            return np.where((x >= 0) & (x <= self.span_m), w, 0.0)
        amps = np.broadcast_to(np.asarray(midspan_m, dtype=np.float64), (self.n_spans,)) \
            if np.ndim(midspan_m) == 0 else np.asarray(midspan_m, dtype=np.float64)
        if amps.shape != (self.n_spans,):
            raise InputError(f"bridge model has {self.n_spans} spans; got {amps.size} midspan displacements")
        if self.deflection_shape == "continuous":
            return continuous_deflection(self.spans_m, amps, x)
        xs = self.support_x_m
        out = np.zeros(x.shape)
        for k, (x0, span) in enumerate(zip(xs[:-1], self.spans_m, strict=False)):
            sel = (x >= x0) & (x <= x0 + span)
            out[sel] = amps[k] * np.sin(np.pi * (x[sel] - x0) / span)
        return out

    def with_targets(self, targets: Sequence[Target]) -> BridgeModel:
        return replace(self, targets=tuple(targets))


def box_mesh(lo: Sequence[float], hi: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and outward triangles (12, 3) of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=np.float64)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], dtype=np.int32)
    return v, f


def deck_mesh(model: BridgeModel, midspan_m: float | Sequence[float], stations: int | None = None, *,
              strain: float = 0.0, fixed_x_m: float = 0.0, strain_across: float = 0.0
              ) -> tuple[np.ndarray, np.ndarray]:
    """The deck as a prism with ``stations`` cross-sections along x, deflected vertically.

    Parameters
    ----------
    model : BridgeModel
    midspan_m : float or (n_spans,) sequence
        Midspan displacement(s), metres, positive up (see :meth:`BridgeModel.deflection_m`).
    stations : int, optional
        Cross-sections along the deck. Default 200 per span.
    strain : float, keyword-only
        Deck strain along x (dL / L, e.g. thermal): every section moves by ``strain * (x - fixed_x_m)``.
        Default 0.
    fixed_x_m : float, keyword-only
        x of the fixed bearing (the point of the deck that does not move along x). Default 0 (the first pier).
    strain_across : float, keyword-only
        Deck strain across (dW / W): the section's width times ``1 + strain_across`` about y = 0. Default 0.

    Returns
    -------
    vertices (4 stations, 3) and triangles, bridge frame, metres.
    """
    stations = 200 * model.n_spans if stations is None else stations
    x = np.linspace(-model.overhang_m, model.length_m + model.overhang_m, stations)
    w = model.deflection_m(x, midspan_m)
    if strain:
        x = x + strain * (x - fixed_x_m)
    hw = model.deck_width_m / 2 * (1.0 + strain_across)
    zb, zt = model.deck_bottom_m, model.deck_bottom_m + model.deck_depth_m
    corners = np.array([[-hw, zb], [hw, zb], [hw, zt], [-hw, zt]])  # (y, z) around the section
    v = np.empty((stations, 4, 3))
    v[:, :, 0] = x[:, None]
    v[:, :, 1] = corners[None, :, 0]
    v[:, :, 2] = corners[None, :, 1] + w[:, None]
    verts = v.reshape(-1, 3)
    faces = []
    for s in range(stations - 1):
        for c in range(4):
            a, b = s * 4 + c, s * 4 + (c + 1) % 4
            faces.append([a, a + 4, b])
            faces.append([b, a + 4, b + 4])
    last = (stations - 1) * 4
    faces += [[0, 1, 2], [0, 2, 3], [last, last + 2, last + 1], [last, last + 3, last + 2]]
    return verts, np.asarray(faces, dtype=np.int32)


def pier_meshes(model: BridgeModel) -> list[tuple[np.ndarray, np.ndarray]]:
    """(vertices, triangles) of each pier's box (one at every support), bridge frame, metres."""
    hl, hw = model.pier_length_m / 2, model.pier_width_m / 2
    return [box_mesh((xc - hl, -hw, 0.0), (xc + hl, hw, model.deck_bottom_m)) for xc in model.support_x_m]


def ground_mesh(model: BridgeModel, extent_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, triangles) of a square of ground centred on the bridge, bridge frame.

    ``extent_m`` is its half-width; default the larger of 150 m and half the bridge's length plus 100 m.
    """
    xc = model.length_m / 2
    extent_m = max(150.0, xc + 100.0) if extent_m is None else extent_m
    v = np.array([[xc - extent_m, -extent_m, 0], [xc + extent_m, -extent_m, 0],
                  [xc + extent_m, extent_m, 0], [xc - extent_m, extent_m, 0]], dtype=np.float64)
    return v, np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def plate_mesh(centre: ArrayLike, normal: ArrayLike, half_size_m: float) -> tuple[np.ndarray, np.ndarray]:
    """A square plate (two-sided) centred on a point, facing ``normal``."""
    e1, e2 = in_plane_axes(normal)
    c = np.asarray(centre, dtype=np.float64)
    v = np.array([c + half_size_m * (sx * e1 + sy * e2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return v, np.array([[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]], dtype=np.int32)


def in_plane_axes(normal: ArrayLike, up_hint: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane normal to ``normal``.

    The second axis is the projection of +z (or of +y for horizontal planes),
    so on a vertical pier face it points up.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    hint = np.array([0.0, 0.0, 1.0]) if up_hint is None else np.asarray(up_hint, dtype=np.float64)
    if abs(np.dot(hint, n)) > 0.9:
        hint = np.array([0.0, 1.0, 0.0])
    e2 = hint - np.dot(hint, n) * n
    e2 /= np.linalg.norm(e2)
    e1 = np.cross(e2, n)
    return e1, e2


def model_to_dict(model: BridgeModel) -> dict:
    """Every parameter of a bridge model and its targets, as JSON-ready values (see :func:`model_from_dict`)."""
    d = {f.name: getattr(model, f.name) for f in fields(model) if f.name != "targets"}
    for k in ("spans_m", "deck_fractions", "girder_lines_m"):
        d[k] = list(d[k])
    d["targets"] = [{"id": t.id, "group": t.group, "centre_m": list(t.centre_m), "normal": list(t.normal),
                     "diameter_m": t.diameter_m} for t in model.targets]
    return d


def model_from_dict(d: dict) -> BridgeModel:
    """The bridge model written by :func:`model_to_dict`."""
    known = {f.name for f in fields(BridgeModel)}
    kw: dict = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in known and k != "targets"}
    targets = tuple(Target(t["id"], t["group"], tuple(t["centre_m"]), tuple(t["normal"]), float(t["diameter_m"]))
                    for t in d.get("targets", ()))
    return BridgeModel(**kw, targets=targets)

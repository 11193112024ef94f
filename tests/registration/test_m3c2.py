"""M3C2 through py4dgeo's compiled core gives py4dgeo.M3C2's distances, levels of detection and normals to the bit."""
from __future__ import annotations

import logging

import numpy as np
import pytest

import registration.change as change
from registration.change import m3c2


def _surfaces(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A gently curved 6 x 4 m surface and the same surface 3 mm lower in its middle, re-sampled, with noise."""
    rng = np.random.default_rng(seed)

    def sample(n, sag):
        xy = rng.uniform([0, 0], [6, 4], (n, 2))
        z = 0.02 * np.sin(xy[:, 0]) - sag * np.exp(-((xy[:, 0] - 3) ** 2) / 2) + rng.normal(0, 0.002, n)
        return np.column_stack([xy + 1000.0, z + 50.0])  # away from the origin, as scans in a project frame

    a, b = sample(40_000, 0.0), sample(35_000, 0.003)
    return a, b, a[::97]


def _package(a, b, core, **kw):
    import py4dgeo

    logging.getLogger("py4dgeo").setLevel(logging.WARNING)
    off = a.mean(axis=0)
    algo = py4dgeo.M3C2(epochs=(py4dgeo.Epoch(a - off), py4dgeo.Epoch(b - off)), corepoints=core - off,
                        normal_radii=list(kw["normal_radii"]), cyl_radius=kw["cyl_radius"],
                        max_distance=kw["max_distance"], registration_error=kw["registration_error"],
                        robust_aggr=kw["robust_aggr"], orientation_vector=np.array([0.0, 0.0, 1.0]))
    d, unc = algo.run()
    return d, unc["lodetection"], algo.directions()


@pytest.mark.parametrize("kw", [
    dict(normal_radii=(0.5,), cyl_radius=0.25, max_distance=0.5, registration_error=0.0002, robust_aggr=False),
    dict(normal_radii=(0.2, 0.4, 0.8), cyl_radius=0.1, max_distance=0.05, registration_error=0.0, robust_aggr=True),
])
def test_the_compiled_core_gives_py4dgeos_m3c2_to_the_bit(kw):
    a, b, core = _surfaces(1)
    ours = m3c2(a, b, core, **kw)
    d, lod, normals = _package(a, b, core, **kw)
    assert np.array_equal(ours.distance_m, d, equal_nan=True)
    assert np.array_equal(ours.lod_m, lod, equal_nan=True)
    assert np.array_equal(ours.normals, normals)
    assert np.isfinite(ours.distance_m).mean() > 0.9 and np.nanmedian(ours.distance_m) < -0.0005


def test_another_py4dgeo_core_falls_back_to_the_package(monkeypatch):
    a, b, core = _surfaces(2)
    kw = dict(normal_radii=(0.5,), cyl_radius=0.25, max_distance=0.5, registration_error=0.0001, robust_aggr=False)
    want = m3c2(a, b, core, **kw)
    calls = []

    def unlike(*args):
        calls.append("core")
        raise change._CoreUnlike("compute_distances(): incompatible function arguments")

    package = change._m3c2_package

    def counted(*args):
        calls.append("package")
        return package(*args)

    monkeypatch.setattr(change, "_m3c2_compiled", unlike)
    monkeypatch.setattr(change, "_m3c2_package", counted)
    got = m3c2(a, b, core, **kw)
    assert calls == ["core", "package"]
    assert np.array_equal(got.distance_m, want.distance_m, equal_nan=True)
    assert np.array_equal(got.lod_m, want.lod_m, equal_nan=True)


def test_a_core_without_the_calls_is_reported_as_unlike(monkeypatch):
    import _py4dgeo

    monkeypatch.delattr(_py4dgeo, "compute_multiscale_directions")
    a, b, core = _surfaces(3)
    with pytest.raises(change._CoreUnlike):
        change._m3c2_compiled(a, b, core, (0.5,), 0.25, 0.5, 0.0, False, np.array([0.0, 0.0, 1.0]))

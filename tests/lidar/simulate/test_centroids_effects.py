"""Centroid-level simulation: multi-span geometry and the systematic errors, against their definitions."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common.errors import InputError
from lidar.simulate import centroids as sc
from lidar.simulate.effects import DriftModel, InverseSquareWalk, LinearIncidenceWalk, return_strength

THREE = sc.BridgeGeometry(spans_m=(39.9, 39.9, 39.9))


def exact(xyz, ids, **kw):
    """Noise-free observations (no noise, no tilt), the scanner rotation and the true scanner-frame positions."""
    obs, rot = sc.observe(xyz, ids, scanner_xyz=(30.0, -15.0, 1.5), heading_deg=35.0, rng=np.random.default_rng(0),
                          range_sigma_m=0.0, angle_sigma_rad=0.0, tilt_deg=0.0, return_rotation=True, **kw)
    socs = (xyz - np.array([30.0, -15.0, 1.5])) @ rot
    return np.array([obs[i].xyz for i in ids]), rot, socs


def test_single_span_geometry_is_unchanged_and_multi_span_has_the_expected_targets():
    ids, groups, xyz = sc.BridgeGeometry().targets()
    assert ids == ("R1", "R2", "R3", "R4", "M1", "M2", "M3", "M4", "M5", "M6")
    np.testing.assert_allclose(xyz[2], [40.0, 0.0, 0.0])
    ids, groups, xyz = THREE.targets()
    assert THREE.span_m == pytest.approx(119.7)
    assert [i for i in ids if groups[i] == "reference"] == [f"R{k}" for k in range(1, 9)]
    assert len([i for i in ids if groups[i] == "measurement"]) == 3 * 2 * 3
    np.testing.assert_allclose(xyz[2:6, 0], [38.9, 40.9, 78.8, 80.8])  # inner piers' two faces
    normals = THREE.normals()
    assert normals.shape == xyz.shape
    np.testing.assert_array_equal(normals[:8, 0], [1, 1, -1, 1, -1, 1, -1, -1])
    assert np.all(normals[8:] == [0, 0, -1])
    with pytest.raises(InputError, match="positive"):
        sc.BridgeGeometry(spans_m=(10.0, 0.0))


def test_multi_span_deflection_is_zero_at_supports_and_the_amplitude_at_midspans():
    g = sc.BridgeGeometry(spans_m=(30.0, 45.0, 30.0), stations=(0.0, 0.5, 1.0), girder_offsets_m=(0.0,))
    ids, groups, xyz = g.targets()
    dz = sc.deflection(xyz, groups, ids, g, midspan_m=0.0, span_amplitudes_m=(-0.004, -0.006, -0.003))
    deck = np.array([groups[i] == "measurement" for i in ids])
    np.testing.assert_allclose(dz[deck].reshape(3, 3)[:, [0, 2]], 0.0, atol=1e-18)
    np.testing.assert_allclose(dz[deck].reshape(3, 3)[:, 1], [-0.004, -0.006, -0.003])
    assert np.all(dz[~deck] == 0)
    with pytest.raises(InputError, match="span amplitudes"):
        sc.deflection(xyz, groups, ids, g, midspan_m=0.0, span_amplitudes_m=(-0.004,))


def test_along_span_movement_is_strain_times_distance_from_the_fixed_bearing():
    ids, groups, xyz = THREE.targets()
    dx = sc.along_span(xyz, groups, ids, strain=3e-4, fixed_x_m=39.9)
    for k, i in enumerate(ids):
        assert dx[k] == (pytest.approx(3e-4 * (xyz[k, 0] - 39.9)) if groups[i] == "measurement" else 0.0)


def test_effects_off_are_the_default_and_draw_no_extra_random_numbers():
    ids, groups, xyz = THREE.targets()
    states = []
    for kw in ({}, {"range_scale_ppm": 20.0, "range_walk": InverseSquareWalk(), "drift": DriftModel(5, 5, 5),
                    "times_s": np.arange(len(ids)) * 60.0, "normals_bridge": THREE.normals()}):
        rng = np.random.default_rng(1)
        sc.observe(xyz, ids, scanner_xyz=(30, -15, 1.5), heading_deg=35.0, rng=rng, **kw)
        states.append(rng.bit_generator.state)
    assert states[0] == states[1]


def test_a_known_ppm_scales_every_range_by_exactly_that():
    ids, _, xyz = THREE.targets()
    got, _, socs = exact(xyz, ids, range_scale_ppm=-30.0)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1) / np.linalg.norm(socs, axis=1), 1 - 30e-6, rtol=1e-14)
    np.testing.assert_allclose(got / np.linalg.norm(got, axis=1)[:, None], socs / np.linalg.norm(socs, axis=1)[:, None],
                               atol=1e-15)


def test_range_walk_acts_along_each_line_of_sight_with_the_incidence_of_its_normal():
    ids, _, xyz = THREE.targets()
    walk = LinearIncidenceWalk(0.0015)
    got, rot, socs = exact(xyz, ids, range_walk=walk, normals_bridge=THREE.normals())
    r = np.linalg.norm(socs, axis=1)
    cos_inc = np.abs(np.einsum("ij,ij->i", THREE.normals() @ rot, socs)) / r
    np.testing.assert_allclose(r - np.linalg.norm(got, axis=1), 0.0015 * cos_inc, atol=1e-12)
    head_on, _, _ = exact(xyz, ids, range_walk=InverseSquareWalk(0.003, 15.0))
    s = return_strength(r, 1.0)
    np.testing.assert_allclose(r - np.linalg.norm(head_on, axis=1), 0.003 * s / (1 + s), atol=1e-12)


def test_drift_rotates_late_targets_by_rate_times_time_about_the_scanner():
    ids, _, xyz = THREE.targets()
    drift = DriftModel(tilt_x_arcsec_per_h=40.0, twist_arcsec_per_h=-25.0)
    times = np.linspace(0.0, 3600.0, len(ids))
    got, _, socs = exact(xyz, ids, drift=drift, times_s=times)
    for k in (0, len(ids) // 2, len(ids) - 1):
        rv = np.radians(np.array([40.0, 0.0, -25.0]) * times[k] / 3600.0 / 3600.0)
        np.testing.assert_allclose(got[k], Rotation.from_rotvec(rv).inv().apply(socs[k]), atol=1e-12)
    np.testing.assert_allclose(got[0], socs[0], atol=1e-15)
    with pytest.raises(InputError, match="times_s"):
        exact(xyz, ids, drift=drift)

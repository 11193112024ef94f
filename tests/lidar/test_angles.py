import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.errors import InputError
from lidar.angles import (
    AngularWindow,
    bounding_window,
    direction_from_angles,
    phi_difference,
    spherical_from_xyz,
    window_around,
)


@given(st.floats(0.5, 179.5), st.floats(0, 359.999), st.floats(0.1, 500))
def test_angles_round_trip(theta, phi, r):
    xyz = direction_from_angles(theta, phi)[None] * r
    t, p, rr = spherical_from_xyz(xyz)
    assert abs(t[0] - theta) < 1e-9 and abs(phi_difference(p[0], phi)) < 1e-8 and abs(rr[0] - r) < 1e-9
    assert 0 <= p[0] < 360


def test_conventions():
    t, p, _ = spherical_from_xyz(np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, -1.0, 0]]))
    np.testing.assert_allclose(t, [90, 90, 0, 90])
    np.testing.assert_allclose(p, [0, 90, 0, 270])


def test_window_across_the_seam():
    w = window_around(90.0, 359.5, 1.0, 1.0, 0.1, 0.1)
    assert w.phi_min_deg < 0 < w.phi_max_deg
    assert w.contains(90.0, 0.3) and w.contains(90.0, 359.0) and not w.contains(90.0, 180.0)
    theta, phi = w.grid()
    assert np.all((phi >= 0) & (phi < 360))
    assert len(theta) == w.n_directions == 21 * 21


def test_bounding_window_is_seam_aware():
    w = bounding_window(np.array([80.0, 95.0]), np.array([358.0, 3.0]), theta_step_deg=0.1, phi_step_deg=0.1)
    assert (w.phi_min_deg, w.phi_max_deg) == pytest.approx((-2.0, 3.0))


def test_invalid_windows():
    with pytest.raises(InputError):
        AngularWindow(10, 5, 80, 90, 0.1, 0.1)
    with pytest.raises(InputError):
        AngularWindow(0, 5, 80, 190, 0.1, 0.1)
    with pytest.raises(InputError):
        AngularWindow(0, 5, 80, 90, float("nan"), 0.1)


def test_the_quick_float32_arctan2_is_within_3e_5_degrees_everywhere():
    from lidar.angles import atan2_deg32

    rng = np.random.default_rng(0)
    y = rng.normal(size=200_000) * 10.0 ** rng.uniform(-6, 3, 200_000)
    x = rng.normal(size=200_000) * 10.0 ** rng.uniform(-6, 3, 200_000)
    y[:8] = [0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 0.0, 0.0]  # the axes and signed zeros
    x[:8] = [1.0, 1.0, -1.0, -1.0, 0.0, 0.0, 0.0, -0.0]
    y32, x32 = y.astype(np.float32), x.astype(np.float32)
    got = atan2_deg32(y32, x32)
    want = np.degrees(np.arctan2(y32.astype(np.float64), x32.astype(np.float64)))
    assert got.dtype == np.float32 and np.abs(got - want).max() < 3e-5
    np.testing.assert_array_equal(got[:8], np.float32([0, -0.0, 180, -180, 90, -90, 0, 180]))
    np.testing.assert_array_equal(np.signbit(got[:8]), np.signbit(want[:8]))
    assert np.array_equal(y32, y.astype(np.float32)) and np.array_equal(x32, x.astype(np.float32))  # untouched


def test_the_float32_spherical_angles_match_the_float64_ones():
    from lidar.angles import spherical32

    xyz = np.random.default_rng(1).normal(size=(50_000, 3)) * 30.0
    t64, p64, r64 = spherical_from_xyz(xyz)
    t, p, r = spherical32(*(xyz[:, k].astype(np.float32) for k in range(3)))
    assert np.abs(t - t64).max() < 3e-5 and np.abs(r - r64).max() < 1e-6 * r64.max()
    # azimuths above 180 take one more rounding (+360, a float32 step of 3e-5 there)
    assert np.all((p >= 0) & (p <= 360)) and np.abs(phi_difference(p, p64)).max() < 5e-5

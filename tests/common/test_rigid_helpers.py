import numpy as np

from common.rigid import rotate_vectors, rotation_from_rotvec, rotations_from_rotvecs, skew


def test_skew_is_the_cross_product_for_one_vector_and_a_stack():
    rng = np.random.default_rng(2)
    v, w = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    np.testing.assert_array_equal(np.einsum("nij,nj->ni", skew(v), w), np.cross(v, w))
    np.testing.assert_allclose(skew(v[0]) @ w[0], np.cross(v[0], w[0]), rtol=0, atol=1e-15)
    assert skew(v[0]).shape == (3, 3)


def test_the_rodrigues_helpers_agree_with_each_other():
    rng = np.random.default_rng(3)
    rotvecs = rng.normal(size=(6, 3))
    rotvecs[0] = 0.0
    stack = rotations_from_rotvecs(rotvecs)
    v = rng.normal(size=(6, 3))
    for k in range(6):
        np.testing.assert_allclose(stack[k], rotation_from_rotvec(rotvecs[k]), atol=1e-14)
    np.testing.assert_allclose(rotate_vectors(v, rotvecs), np.einsum("nij,nj->ni", stack, v), atol=1e-14)

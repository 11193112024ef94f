"""The rigid-motion helpers every package shares."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from common.rigid import matrix_from_rotvec, rotation_from_rotvec


@pytest.mark.parametrize("w", [(0.0, 0.0, 0.0), (1e-17, 0.0, 0.0), (2e-6, -1e-6, 3e-6), (0.3, -0.2, 1.1),
                               (np.pi, 0.0, 0.0)])
def test_rotation_from_rotvec_is_rodrigues_as_scipy_has_it(w):
    np.testing.assert_allclose(rotation_from_rotvec(w), Rotation.from_rotvec(w).as_matrix(), atol=1e-14)
    r = rotation_from_rotvec(w)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)


def test_matrix_from_rotvec_carries_the_translation():
    m = matrix_from_rotvec((0.0, 0.0, np.pi / 2), (1.0, 2.0, 3.0))
    np.testing.assert_allclose(m @ np.array([1.0, 0.0, 0.0, 1.0]), [1.0, 3.0, 3.0, 1.0], atol=1e-12)

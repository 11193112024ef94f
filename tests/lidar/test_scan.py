import numpy as np
import pytest

from common.errors import InputError
from lidar.scan import Scan


def test_validates_shapes_and_dtypes():
    with pytest.raises(InputError, match="float64"):
        Scan(xyz_socs=np.zeros((3, 3), np.float32))
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        Scan(xyz_socs=np.zeros((3, 2)))
    with pytest.raises(InputError, match="intensity"):
        Scan(xyz_socs=np.zeros((3, 3)), intensity=np.zeros(2, np.float32))


def test_world_subset_concatenate(small_scan):
    world = small_scan.xyz_world()
    np.testing.assert_allclose(world - small_scan.xyz_socs, np.tile([100.0, 200.0, 10.0], (len(small_scan), 1)))
    sub = small_scan.subset(small_scan.intensity > 0.5)
    assert 0 < len(sub) < len(small_scan) and np.all(sub.intensity > 0.5)
    both = Scan.concatenate([sub, small_scan])
    assert len(both) == len(sub) + len(small_scan)
    with pytest.raises(AttributeError):
        small_scan.name = "x"  # frozen

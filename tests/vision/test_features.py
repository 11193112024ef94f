"""Feature detection: circle centres and checkerboard corners, sub-pixel; clean refusals."""
import numpy as np
import pytest

from common.errors import InputError, ProcessingError
from vision.features import detect_checkerboard, detect_circles, match_pattern
from vision.simulate import SyntheticRig
from vision.simulate.rig import die_pattern


def test_circle_centres_are_sub_pixel_with_noise():
    rig = SyntheticRig()
    rng = np.random.default_rng(3)
    for d in ([0.0, 0.0], [0.0123, -0.0071]):
        img = rig.render_main(np.eye(4), d, noise=0.01, rng=rng)
        det = detect_circles(img)
        assert len(det.centres_px) == 5 and np.all(det.circularity > 0.85)
        uv = match_pattern(det.centres_px, rig.geometry.main_pattern_m)
        assert np.abs(uv - rig.main_image_points(np.eye(4), d)).max() < 0.05


def test_pattern_matching_resolves_the_symmetric_die_pattern():
    pattern = die_pattern()
    true = np.array([[100.0, 50.0], [250.0, 52.0], [175.0, 110.0], [98.0, 170.0], [248.0, 172.0]])
    shuffled = true[[4, 2, 0, 3, 1]]
    assert np.allclose(match_pattern(shuffled, pattern), true)
    with pytest.raises(ProcessingError, match="3 circles, 5 expected"):
        match_pattern(true[:3], pattern)


def test_checkerboard_order_is_canonical_even_when_the_image_is_rotated_half_a_turn():
    rig = SyntheticRig()
    img = rig.render_sub(np.eye(4))
    c0 = detect_checkerboard(img, rig.geometry.board.inner_corners)
    c1 = detect_checkerboard(img[::-1, ::-1].copy(), rig.geometry.board.inner_corners)
    h, w = img.shape
    flipped = np.column_stack([w - 1 - c1[:, 0], h - 1 - c1[:, 1]])[::-1]
    assert c0[0, 0] < c0[-1, 0] and c0[0, 1] < c0[-1, 1]
    assert np.abs(flipped - c0).max() < 0.05


def test_missing_board_and_bad_images():
    assert detect_checkerboard(np.zeros((200, 300), np.uint8), (12, 7)) is None
    with pytest.raises(InputError, match="NaN"):
        detect_circles(np.full((50, 50), np.nan))
    with pytest.raises(InputError, match="shape"):
        detect_circles(np.zeros((4, 5, 6, 7)))

"""The synthetic rig: its projections agree with its rendered images, and motions are relative to frame 1."""
import numpy as np

from vision.features import detect_checkerboard, detect_main_target
from vision.geometry import invert, rigid_from_rotvec
from vision.simulate import RigGeometry, SyntheticRig, table10_schedule


def test_geometry_of_the_numerical_study():
    g = RigGeometry()
    # main and sub targets 10 m apart, cameras 80 mm apart, fields of view ~200 and ~150 mm wide
    main_c = g.main_points_world()[2]
    sub_c = g.B_ws_to_world[:3, 3] + g.board.centre_ws
    assert abs(np.linalg.norm(main_c - sub_c) - 10.0) < 0.01
    assert g.baseline_m == 0.08
    w = g.resolution[0]
    assert abs(w / g.K_main[0, 0] * g.main_distance_m - 0.20) < 1e-9
    assert abs(w / g.K_sub[0, 0] * g.sub_distance_m - 0.15) < 1e-9


def test_target_displacement_up_moves_the_image_up():
    rig = SyntheticRig()
    p0 = rig.main_image_points(np.eye(4))
    p1 = rig.main_image_points(np.eye(4), [0.0, 0.002])
    dv = (p1 - p0)[:, 1]
    assert np.all(dv < -15)  # 2 mm at ~0.104 mm/px is ~19 px, and up is -v
    assert np.allclose((p1 - p0)[:, 0], 0, atol=0.5)


def test_rig_rotation_gives_the_lever_arm_false_displacement():
    rig = SyntheticRig()
    pose = rigid_from_rotvec([1e-3, 0, 0], [0, 0, 0])  # 1 mrad about x of CS(1)
    d = rig.main_image_points(pose) - rig.main_image_points(np.eye(4))
    mm = np.linalg.norm(d.mean(axis=0)) * 0.2 / 1920 * 1e3
    assert 9.0 < mm < 11.0  # ~ 1 mrad x ~ 9.9 m


def test_rendered_images_match_exact_projections():
    rig = SyntheticRig()
    g = rig.geometry
    pose = rigid_from_rotvec([3e-4, -2e-4, 5e-4], [0.002, -0.001, 0.003])
    uv = detect_main_target(rig.render_main(pose, [0.001, -0.003]), g.main_pattern_m)
    assert np.abs(uv - rig.main_image_points(pose, [0.001, -0.003])).max() < 0.02
    corners = detect_checkerboard(rig.render_sub(pose), g.board.inner_corners)
    err = corners - rig.sub_image_points(pose)
    assert np.sqrt((err ** 2).mean()) < 0.05 and np.abs(err).max() < 0.1


def test_table10_schedule_starts_at_rest_and_respects_bounds():
    P = table10_schedule(frames_per_block=20)
    assert P.shape == (140, 4, 4)
    assert np.allclose(P[0], np.eye(4))
    assert np.abs(P[:, :3, 3]).max() <= 0.01 + 1e-12
    assert np.allclose(invert(invert(P)), P)

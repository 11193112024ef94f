"""The dual-camera method against the synthetic rig's ground truth."""
import numpy as np
import pytest

from common.errors import InputError, ProcessingError
from vision.compensation import calibrate_dual_camera, fit_false_displacement, measure_dual_camera
from vision.main_camera import fit_affine_target
from vision.simulate import RigGeometry, SyntheticRig, calibration_motions, table10_schedule
from vision.simulate.motions import pan_tilt_drift
from vision.sub_camera import calibrate_intrinsics, exact_intrinsics, motion_from_poses, solve_poses


def test_affine_target_model_recovers_pixels_per_mm():
    rig = SyntheticRig()
    g = rig.geometry
    m = fit_affine_target(g.main_pattern_m, rig.main_image_points(np.eye(4)))
    assert abs(m.mm_per_px - 0.2 / 1920 * 1e3) < 0.002
    assert m.residual_px < 0.05  # the perspective camera is affine to well below a pixel here
    d = m.to_metres(rig.main_image_points(np.eye(4), [0.0, 0.004]) - rig.main_image_points(np.eye(4)))
    assert np.allclose(d, [0.0, 0.004], atol=2e-5)
    with pytest.raises(InputError, match="at least 3"):
        fit_affine_target(g.main_pattern_m[:2], rig.main_image_points(np.eye(4))[:2])
    with pytest.raises(InputError, match="collinear"):
        fit_affine_target(np.array([[0, 0], [1, 1], [2, 2.0]]), np.array([[0, 0], [1, 1], [2, 2.0]]))


def test_zhang_calibration_and_poses_recover_the_motion():
    rig = SyntheticRig()
    g = rig.geometry
    intr = calibrate_intrinsics(g.board.object_points(), rig.zhang_views(12), g.resolution)
    assert np.allclose(intr.K, g.K_sub, rtol=1e-4, atol=0.05) and intr.rms_px < 1e-3
    poses = calibration_motions(8, rotation_rad=1e-3, translation_m=0.01)
    _, sub = rig.sequence(poses)
    motion = solve_poses(g.board.object_points(), sub, intr)
    exact = motion_from_poses(poses)
    assert np.abs(motion.R - exact.R).max() < 1e-6 and np.abs(motion.T - exact.T).max() < 1e-7
    with pytest.raises(InputError, match="at least 3 views"):
        calibrate_intrinsics(g.board.object_points(), rig.zhang_views(2), g.resolution)


def test_nine_unknowns_are_recovered_without_quantisation():
    rig = SyntheticRig()
    poses = calibration_motions(21, rotation_rad=1e-3, translation_m=0.01)
    main, _ = rig.sequence(poses)
    cal = fit_false_displacement(main, motion_from_poses(poses))
    assert cal.n_motions == 21 and np.all(cal.residual_px < 0.2)
    # X_i: the features' positions in CS(1) -- ~9.9 m behind the sub-camera
    assert np.allclose(cal.X_cs1, rig.geometry.main_points_world(), atol=0.05)


def exact_setup(rig, h):
    """The calibration stage from exact projections of ``h`` rig motions (no quantisation)."""
    g = rig.geometry
    main, sub = rig.sequence(calibration_motions(h, rotation_rad=1e-3, translation_m=0.01))
    return calibrate_dual_camera(main, sub, pattern_m=g.main_pattern_m, board_points_m=g.board.object_points(),
                                 intrinsics=exact_intrinsics(g.K_sub, g.resolution))


def test_compensation_removes_the_false_displacement_of_table10_motions():
    rig = SyntheticRig()
    setup = exact_setup(rig, 21)
    P = table10_schedule(frames_per_block=30)
    truth = np.column_stack([np.zeros(len(P)), -0.003 * np.sin(np.linspace(0, 3, len(P)))])
    main, sub = rig.sequence(P, truth)
    res = measure_dual_camera(setup, main, sub)
    single_err = np.abs(res.single_camera_m - truth).max()
    dual_err = np.abs(res.displacement_m - truth).max()
    assert single_err > 0.01          # ~1 mrad over ~10 m and 10 mm translations: centimetres
    assert dual_err < 5e-5            # without quantisation the method leaves ~0
    assert res.valid.all() and res.sigma_m.shape == (len(P), 2)
    assert np.allclose(res.false_displacement_m, res.single_camera_m - truth, atol=5e-5)


@pytest.mark.slow
def test_lab_size_false_displacement_is_reduced_below_the_dissertations_1_1_mm():
    """From rendered 1920x1200 images with sub-pixel detection (the lab's hardware and geometry)."""
    from vision.features import detect_checkerboard, detect_main_target

    g = RigGeometry.laboratory()
    rig = SyntheticRig(g)

    def detect(poses, disp):
        m = [detect_main_target(rig.render_main(P, d), g.main_pattern_m) for P, d in zip(poses, disp, strict=False)]
        s = [detect_checkerboard(rig.render_sub(P), g.board.inner_corners) for P in poses]
        return np.array(m), np.array(s)

    cal = calibration_motions(21, rotation_rad=3e-3, translation_m=0.005)
    main, sub = detect(cal, np.zeros((len(cal), 2)))
    intr = calibrate_intrinsics(g.board.object_points(), rig.zhang_views(12, quantise=False), g.resolution)
    setup = calibrate_dual_camera(main, sub, pattern_m=g.main_pattern_m, board_points_m=g.board.object_points(),
                                  intrinsics=intr)
    P = pan_tilt_drift(12)
    truth = np.column_stack([np.zeros(len(P)), np.linspace(0, -0.004, len(P))])
    main, sub = detect(P, truth)
    res = measure_dual_camera(setup, main, sub)
    false_mm = np.linalg.norm(res.single_camera_m - truth, axis=1).max() * 1e3
    err_mm = np.abs(res.displacement_m - truth).max() * 1e3
    assert false_mm > 40.0
    assert err_mm < 1.1
    # the reported sigma is honest: errors within 3 sigma
    assert np.all(np.abs(res.displacement_m - truth)[:, 1] < 3 * res.sigma_m[:, 1] + 1e-4)


def test_missing_frames_are_flagged_not_invented():
    rig = SyntheticRig()
    setup = exact_setup(rig, 10)
    main, sub = rig.sequence(calibration_motions(10, rotation_rad=1e-3, translation_m=0.01)[:4])
    main[1] = np.nan
    sub[2] = np.nan
    res = measure_dual_camera(setup, main, sub)
    assert list(res.valid) == [True, False, False, True]
    assert res.flags[1] == ("main_target_missing",) and res.flags[2] == ("sub_target_missing",)
    assert np.isnan(res.displacement_m[1]).all() and np.isnan(res.displacement_m[2]).all()


def test_calibration_refuses_motions_that_do_not_excite_every_axis():
    rig = SyntheticRig()
    poses = calibration_motions(21, rotation_rad=1e-3, translation_m=0.0)
    main, _ = rig.sequence(poses)
    with pytest.raises(ProcessingError, match="every axis"):
        fit_false_displacement(main, motion_from_poses(poses))
    with pytest.raises(ProcessingError, match="at least 6"):
        fit_false_displacement(main[:4], motion_from_poses(poses[:4]))


def test_the_dissertations_fields_of_view_on_a_16_10_sensor():
    """200 x 150 mm (main) and 150 x 100 mm (sub) fields on 1920 x 1200 pixels: non-square pixels, and the
    method still removes the false displacement without quantisation."""
    g = RigGeometry(main_fov_m=0.20, main_fov_h_m=0.15, sub_fov_m=0.15, sub_fov_h_m=0.10)
    w, h = g.resolution
    assert np.isclose(w * g.main_distance_m / g.K_main[0, 0], 0.20)
    assert np.isclose(h * g.main_distance_m / g.K_main[1, 1], 0.15)
    assert np.isclose(h * g.sub_distance_m / g.K_sub[1, 1], 0.10)
    rig = SyntheticRig(g)
    m = fit_affine_target(g.main_pattern_m, rig.main_image_points(np.eye(4)))
    assert m.residual_px < 0.05
    intr = calibrate_intrinsics(g.board.object_points(), rig.zhang_views(12), g.resolution)
    assert np.allclose(intr.K, g.K_sub, rtol=1e-4, atol=0.05)
    setup = exact_setup(rig, 21)
    poses = table10_schedule(frames_per_block=10)
    main, sub = rig.sequence(poses)
    res = measure_dual_camera(setup, main, sub)
    assert np.abs(res.displacement_m).max() < 1e-4
    assert np.abs(res.single_camera_m[:, 1]).max() > 5e-3

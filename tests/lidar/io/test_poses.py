"""Scans in a project frame: the test, the pose files (SOP, Cyclone text), the carry into the scanner frame."""
from __future__ import annotations

import numpy as np
import pytest

from common.errors import InputError
from lidar.io import write_scan
from lidar.io.info import describe_file
from lidar.io.poses import (
    FileFrame,
    carry_to_scanner,
    file_frames,
    in_project_frame,
    pose_from_origin,
    read_in_scanner_frame,
    read_pose_file,
)
from lidar.scan import Scan
from lidar.simulate.visits import project_transform, write_sop


def _pose(seed: int = 0) -> np.ndarray:
    return project_transform(np.random.default_rng(seed), tilt_deg=0.5)


def _scan(n: int = 400, seed: int = 1, pose=None) -> Scan:
    rng = np.random.default_rng(seed)
    xyz = rng.uniform([-30, -30, -2], [30, 30, 8], (n, 3))
    return Scan(xyz, rng.uniform(0, 1, n).astype(np.float32), pose=pose, name="s")


def _exported(scan: Scan, pose: np.ndarray) -> Scan:
    """The scan as a registered export writes it: points in the project frame, no pose."""
    return Scan(scan.xyz_socs @ pose[:3, :3].T + pose[:3, 3], scan.intensity, name=scan.name)


def test_the_project_frame_test_is_the_nearest_point_beyond_2_km():
    s = _scan()
    assert not in_project_frame(s.xyz_socs)
    assert in_project_frame(_exported(s, _pose()).xyz_socs)
    assert not in_project_frame(np.zeros((0, 3)))


def test_a_pose_file_reads_as_riscan_and_cyclone_write_it(tmp_path):
    m = _pose()
    sop = write_sop(tmp_path / "sop.txt", m, comment="scan position 3")
    assert np.allclose(read_pose_file(sop), m, atol=1e-6)
    cyclone = tmp_path / "cyclone.txt"  # commas, a trailing comment, a blank line, the translation in the last row
    rows = [", ".join(f"{v:.9f}" for v in row) for row in m.T]
    cyclone.write_text("# Cyclone registration\n\n" + "\n".join(rows[:2]) + "  # rows\n" + "\n".join(rows[2:]) + "\n")
    assert np.allclose(read_pose_file(cyclone), m, atol=1e-6)


@pytest.mark.parametrize("text, says", [
    ("1 0 0 0\n0 1 0 0\n0 0 1 0\n", "4 rows of 4 numbers"),
    ("1 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "4 rows of 4 numbers"),
    ("1 0 0 x\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "line 1"),
    ("2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "not a rotation"),
    ("1 0 0 5\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "last row"),
    ("", "no numbers"),
])
def test_a_bad_pose_file_is_one_line_naming_it(tmp_path, text, says):
    p = tmp_path / "bad.txt"
    p.write_text(text)
    with pytest.raises(InputError, match=says) as err:
        read_pose_file(p)
    assert str(p) in str(err.value) and len(str(err.value).splitlines()) == 1
    with pytest.raises(InputError, match="not found"):
        read_pose_file(tmp_path / "missing.txt")


def test_the_carry_gives_the_scanner_frame_back_and_keeps_the_pose():
    s, m = _scan(), _pose(3)
    back = carry_to_scanner(_exported(s, m), m)
    assert np.allclose(back.xyz_socs, s.xyz_socs, atol=1e-8) and np.allclose(back.pose, m)
    assert np.allclose(back.xyz_world(), _exported(s, m).xyz_socs, atol=1e-8)


def test_an_origin_alone_makes_a_levelled_pose():
    m = pose_from_origin([2.5e6, 5.6e6, 110.0])
    assert np.allclose(m[:3, :3], np.eye(3)) and np.allclose(m[:3, 3], [2.5e6, 5.6e6, 110.0])
    up = np.array([0.01, -0.02, 1.0])
    r = pose_from_origin([0, 0, 0], up)[:3, :3]
    assert np.allclose(r @ [0, 0, 1], up / np.linalg.norm(up)) and np.allclose(r @ r.T, np.eye(3))
    with pytest.raises(InputError, match="--up"):
        pose_from_origin([0, 0, 0], [0, 0, 0])


def test_file_frames_refuse_a_project_frame_file_without_a_pose_in_one_line(tmp_path):
    s, m = _scan(), _pose()
    socs = write_scan(s, tmp_path / "socs.laz")
    far = write_scan(_exported(s, m), tmp_path / "far.laz")
    assert [f.to_json() for f in file_frames(socs)] == [FileFrame().to_json()]
    with pytest.raises(InputError) as err:
        file_frames(far)
    msg = str(err.value)
    assert str(far) in msg and "project frame" in msg and "--pose" in msg and "--origin" in msg
    assert len(msg.splitlines()) == 1
    given = FileFrame(pose=m, carry=True, source="pose", given="sop.txt")
    (frame,) = file_frames(far, given=given)
    assert frame.carry and np.allclose(read_in_scanner_frame(far, frame).xyz_socs, s.xyz_socs, atol=2e-5)
    (fallback,) = file_frames(far, fallback=given)  # the set-up's own pose, known from its coarse scan
    assert fallback.carry and fallback.source == "pose"
    inverse = FileFrame(pose=np.linalg.inv(m), carry=True, source="pose", given="inverse.txt")
    with pytest.raises(InputError, match="inverted") as err:
        file_frames(far, given=inverse)
    assert "inverse.txt" in str(err.value) and len(str(err.value).splitlines()) == 1


def test_a_file_whose_own_pose_carries_it_is_read_in_the_scanner_frame(tmp_path):
    s, m = _scan(), _pose(5)
    far = write_scan(Scan(_exported(s, m).xyz_socs, s.intensity, pose=m), tmp_path / "posed.laz")
    (frame,) = file_frames(far)
    assert frame.carry and frame.source == "file"
    assert np.allclose(read_in_scanner_frame(far, frame).xyz_socs, s.xyz_socs, atol=2e-5)


def test_an_e57_of_two_scan_positions_is_two_set_ups(tmp_path):
    from lidar.io.e57 import write_e57

    a = _scan(seed=2, pose=_pose(1))
    b = _scan(seed=3, pose=_pose(2))
    c = _scan(seed=4, pose=_pose(1))  # a second scan from the first position
    path = write_e57([a, b, c], tmp_path / "two.e57")
    frames = file_frames(path)
    assert [f.scans for f in frames] == [(0, 2), (1,)] and all(not f.carry for f in frames)
    both = read_in_scanner_frame(path, frames[0])
    assert len(both) == len(a) + len(c) and np.allclose(both.xyz_socs[:len(a)], a.xyz_socs, atol=1e-6)
    with pytest.raises(InputError, match="one --pose"):
        file_frames(path, given=FileFrame(pose=np.eye(4), carry=True, source="pose"))


def test_info_says_project_frame(tmp_path):
    s, m = _scan(), _pose()
    info = describe_file(write_scan(_exported(s, m), tmp_path / "far.laz"))
    assert info.scans[0].frame == "project"
    assert any("project frame" in p and "--pose" in p for p in info.scans[0].problems)
    assert describe_file(write_scan(s, tmp_path / "near.laz")).scans[0].frame == "scanner"

import numpy as np
import pytest

from common.errors import ScanFormatError
from lidar.io import read_scan, read_scans, write_scan


def test_reads_libe57_example(data_dir):
    scan = read_scan(data_dir / "e57" / "bunnyDouble.e57")
    assert len(scan) == 30571
    assert scan.intensity is None  # the file has none: absent, not invented
    np.testing.assert_allclose(scan.pose, np.eye(4))


def test_reads_third_party_file_with_colour_fields(data_dir):
    scan = read_scan(data_dir / "e57" / "ColourRepresentation.e57")
    assert len(scan) == 153
    assert np.all(np.isfinite(scan.xyz_socs))


@pytest.mark.parametrize("name, message", [("bad-crc.e57", "checksum"), ("ZeroPoints.e57", "no points")])
def test_refuses_broken_files_in_one_line(data_dir, name, message, capfd):
    with pytest.raises(ScanFormatError) as err:
        read_scans(data_dir / "e57" / name)
    text = str(err.value)
    assert name in text and message in text and "\n" not in text
    assert "Debug info" not in capfd.readouterr().err  # the C++ library's dump stays quiet


def test_round_trip_with_pose_and_several_scans(tmp_path, small_scan):
    path = tmp_path / "two.e57"
    from lidar.io.e57 import write_e57
    from lidar.scan import Scan

    second = Scan(xyz_socs=small_scan.xyz_socs[:100] + 1, intensity=small_scan.intensity[:100],
                  intensity_raw=small_scan.intensity_raw[:100], name="second")
    write_e57([small_scan, second], path)
    scans = read_scans(path)
    assert [len(s) for s in scans] == [len(small_scan), 100]
    np.testing.assert_allclose(scans[0].xyz_socs, small_scan.xyz_socs, atol=1e-9)
    np.testing.assert_allclose(scans[0].pose, small_scan.pose, atol=1e-12)
    np.testing.assert_allclose(scans[0].intensity, small_scan.intensity, atol=1e-6)
    assert scans[1].name == "second"
    with pytest.raises(ScanFormatError, match="holds 2 scans"):
        read_scan(path)
    assert write_scan(small_scan, tmp_path / "one.e57").exists()

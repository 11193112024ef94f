import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from common.errors import InputError, ScanFormatError
from lidar.io import read_scan, read_scans, sniff_format, write_scan
from lidar.io.ptx import write_ptx


@pytest.mark.parametrize("suffix", [".ply", ".pcd", ".xyz", ".ptx"])
def test_round_trip(tmp_path, small_scan, suffix):
    back = read_scan(write_scan(small_scan, tmp_path / f"s{suffix}"))
    tol = 1e-6 if suffix in (".ptx",) else (1e-5 if suffix == ".xyz" else 0)
    assert np.max(np.abs(back.xyz_socs - small_scan.xyz_socs)) <= tol
    np.testing.assert_allclose(back.intensity, small_scan.intensity, atol=2e-5)
    if suffix in (".pcd", ".ptx"):
        np.testing.assert_allclose(back.pose, small_scan.pose, atol=1e-9)


def test_ascii_ply_and_named_intensity(tmp_path):
    text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n" \
           "property float scalar_Intensity\nend_header\n0 0 1 10\n1 0 1 20\n0 1 1 30\n"
    p = tmp_path / "a.ply"
    p.write_text(text)
    scan = read_scan(p)
    np.testing.assert_allclose(scan.intensity, [0, 0.5, 1.0])


def test_xyz_with_header_and_commas(tmp_path):
    p = tmp_path / "pts.txt"
    p.write_text("//X,Y,Z,R,G,B,Intensity\n1,2,3,255,0,0,0.5\n4,5,6,0,255,0,0.25\n7,8,9,0,0,0,1.0\n")
    scan = read_scan(p)
    np.testing.assert_allclose(scan.intensity_raw, [0.5, 0.25, 1.0])
    np.testing.assert_allclose(scan.xyz_socs[2], [7, 8, 9])


def test_xyz_nan_rows_are_dropped_and_counted(tmp_path):
    p = tmp_path / "n.xyz"
    p.write_text("1 2 3 4\nnan 1 1 1\n2 3 4 5\n")
    scan = read_scan(p)
    assert len(scan) == 2 and scan.metadata["dropped_nonfinite_points"] == 1


def test_xyz_all_nan_is_refused(tmp_path):
    p = tmp_path / "n.xyz"
    p.write_text("nan 1 1 1\n")
    with pytest.raises(ScanFormatError, match="no valid points"):
        read_scan(p)


def test_ptx_grid_multi_scan_and_missing_returns(tmp_path, small_scan):
    one = small_scan.subset(np.arange(10))
    p = write_ptx(one, tmp_path / "a.ptx")
    text = p.read_text()
    lines = text.splitlines()
    lines[10 + 3] = "0 0 0 0.5"  # a grid cell without a return
    (tmp_path / "b.ptx").write_text("\n".join(lines + lines) + "\n")
    scans = read_scans(tmp_path / "b.ptx")
    assert len(scans) == 2 and len(scans[0]) == 9
    assert scans[0].grid_index[:, 0].tolist() == [0, 1, 2, 4, 5, 6, 7, 8, 9]


def test_ptx_truncated(tmp_path, small_scan):
    p = write_ptx(small_scan.subset(np.arange(10)), tmp_path / "a.ptx")
    lines = p.read_text().splitlines()
    (tmp_path / "cut.ptx").write_text("\n".join(lines[:15]))
    with pytest.raises(ScanFormatError, match="cut.ptx: truncated"):
        read_scan(tmp_path / "cut.ptx")


def test_pcd_ascii_and_truncated_binary(tmp_path, small_scan):
    p = tmp_path / "a.pcd"
    p.write_text("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
                 "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1 2 3 0.1\n4 5 6 0.9\n")
    scan = read_scan(p)
    assert scan.pose is None and len(scan) == 2
    b = write_scan(small_scan, tmp_path / "b.pcd")
    blob = b.read_bytes()
    (tmp_path / "cut.pcd").write_bytes(blob[: len(blob) - 100])
    with pytest.raises(ScanFormatError, match="cut.pcd: truncated"):
        read_scan(tmp_path / "cut.pcd")


def _lzf_literal(data: bytes) -> bytes:
    out = bytearray()
    for i in range(0, len(data), 32):
        chunk = data[i:i + 32]
        out.append(len(chunk) - 1)
        out += chunk
    return bytes(out)


@settings(max_examples=30)
@given(st.binary(min_size=1, max_size=300))
def test_lzf_codec_reads_hand_made_literal_streams(data):
    # the stream layout written by hand here is the one PCL writes; the C codec must agree
    import lzf

    assert lzf.decompress(_lzf_literal(data), len(data)) == data


def test_pcd_binary_compressed(tmp_path):
    xyz = np.arange(12, dtype="<f4").reshape(4, 3)
    inten = np.array([0, 1, 2, 3], "<f4")
    body = xyz[:, 0].tobytes() + xyz[:, 1].tobytes() + xyz[:, 2].tobytes() + inten.tobytes()
    comp = _lzf_literal(body)
    head = (b"VERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 4\n"
            b"HEIGHT 1\nVIEWPOINT 1 2 3 1 0 0 0\nPOINTS 4\nDATA binary_compressed\n")
    p = tmp_path / "c.pcd"
    p.write_bytes(head + np.array([len(comp), len(body)], "<u4").tobytes() + comp)
    scan = read_scan(p)
    np.testing.assert_allclose(scan.xyz_socs, xyz)
    np.testing.assert_allclose(scan.intensity, [0, 1 / 3, 2 / 3, 1], atol=1e-6)
    np.testing.assert_allclose(scan.pose[:3, 3], [1, 2, 3])


def test_unsupported_and_wrong_format(tmp_path, small_scan):
    (tmp_path / "a.docx").write_bytes(b"PK\x03\x04")
    with pytest.raises(ScanFormatError, match="unsupported scan format '.docx'"):
        sniff_format(tmp_path / "a.docx")
    (tmp_path / "fake.e57").write_text("hello")
    with pytest.raises(ScanFormatError, match="does not start like a E57 file"):
        read_scan(tmp_path / "fake.e57")
    (tmp_path / "bin.xyz").write_bytes(bytes(range(256)))
    with pytest.raises(ScanFormatError, match="bin.xyz"):
        read_scan(tmp_path / "bin.xyz")
    with pytest.raises(InputError, match="cannot write"):
        write_scan(small_scan, tmp_path / "x.obj")

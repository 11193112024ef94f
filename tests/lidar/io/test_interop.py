"""Files as other tools write them: PDAL, CloudCompare, Cyclone (PTX, PTS), SCENE, RiSCAN, PCL, LAS 1.0-1.4."""
from __future__ import annotations

import shutil
import subprocess

import laspy
import numpy as np
import pytest

from common.errors import ScanFormatError
from lidar.io import read_scan, read_scans, write_scan
from tests.lidar.io.fuzz_cases import e57_with_xml, sample_scan

PCL = shutil.which("pcl_convert_pcd_ascii_binary") is not None
XYZ = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.5], [-7.25, 8.0, 9.0]])


def _check(scan, intensity_raw=None):
    np.testing.assert_allclose(scan.xyz_socs, XYZ, atol=1e-9)
    if intensity_raw is not None:
        np.testing.assert_allclose(scan.intensity_raw, intensity_raw)


@pytest.mark.parametrize("sep", [" ", "\t", ","])
def test_pdal_pcd_ascii_capital_fields_any_separator(tmp_path, sep):
    rows = "\n".join(sep.join(f"{v:g}" for v in (*xyz, i, 1)) for xyz, i in zip(XYZ, (10, 200, 30), strict=False))
    head = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS X Y Z Intensity ReturnNumber\n"
            "SIZE 8 8 8 2 1\nTYPE F F F U U\nCOUNT 1 1 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
            "POINTS 3\nDATA ascii\n")
    p = tmp_path / "pdal.pcd"
    p.write_text(head + rows + "\n")
    scan = read_scan(p)
    _check(scan, [10, 200, 30])
    assert scan.metadata["intensity_convention"] == "8-bit 0..255"


def test_pcd_binary_with_padding_fields_and_counts(tmp_path):
    rec = np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("_", "u1", (4,)), ("intensity", "<f4")])
    rec["x"], rec["y"], rec["z"] = XYZ.T
    rec["intensity"] = (0.1, 0.5, 0.9)
    head = (b"VERSION 0.7\nFIELDS x y z _ intensity\nSIZE 4 4 4 1 4\nTYPE F F F U F\nCOUNT 1 1 1 4 1\nWIDTH 3\n"
            b"HEIGHT 1\nPOINTS 3\nDATA binary\n")
    p = tmp_path / "pad.pcd"
    p.write_bytes(head + rec.tobytes())
    scan = read_scan(p)
    np.testing.assert_allclose(scan.xyz_socs, XYZ.astype(np.float32))
    assert scan.metadata["intensity_convention"] == "unit float 0-1"
    np.testing.assert_allclose(scan.intensity, [0.1, 0.5, 0.9], atol=1e-6)


def _ply_head(lines):
    return ("\r\n".join(lines) + "\r\n").encode()


def test_ply_variants_trailing_blank_crlf_comments_lists_and_scalar_fields(tmp_path):
    head = _ply_head(["ply ", "format ascii 1.0  ", "comment Created by CloudCompare v2.13", "obj_info generated",
                      "element vertex 3", "property double x", "property double y", "property double z",
                      "property float scalar_Intensity", "element face 1",
                      "property list uchar int vertex_indices", "end_header "])
    body = "".join(f"{x} {y} {z} {i}\r\n" for (x, y, z), i in zip(XYZ, (-12.5, 0.0, 3.0), strict=False)) + "3 0 1 2\r\n"
    p = tmp_path / "cc.ply"
    p.write_bytes(head + body.encode())
    scan = read_scan(p)
    _check(scan, [-12.5, 0.0, 3.0])
    assert scan.metadata["intensity_convention"] == "Riegl reflectance dB"


def test_binary_ply_with_capital_names_and_crlf_header(tmp_path):
    rec = np.zeros(3, dtype=[("X", "<f8"), ("Y", "<f8"), ("Z", "<f8"), ("Intensity", "<u2")])
    rec["X"], rec["Y"], rec["Z"] = XYZ.T
    rec["Intensity"] = (0, 1000, 2047)
    head = _ply_head(["ply", "format binary_little_endian 1.0", "element vertex 3", "property double X",
                      "property double Y", "property double Z", "property ushort Intensity", "end_header"])
    p = tmp_path / "faro.ply"
    p.write_bytes(head + rec.tobytes())
    scan = read_scan(p)
    _check(scan, [0, 1000, 2047])
    assert scan.metadata["intensity_convention"] == "FARO 11-bit 0..2047"


def test_cyclone_pts_with_count_line_and_rgb(tmp_path):
    p = tmp_path / "cyclone.pts"
    p.write_text("3\n" + "".join(f"{x} {y} {z} {i} 10 20 30\n"
                                  for (x, y, z), i in zip(XYZ, (-2048, 0, 2047), strict=True)))
    scan = read_scan(p)
    _check(scan, [-2048, 0, 2047])
    assert scan.metadata["format"] == "PTS"
    assert scan.metadata["intensity_convention"] == "Leica PTS -2048..2047"
    p.write_text("30\n" + "".join(f"{x} {y} {z} 1 10 20 30\n" for x, y, z in XYZ))
    with pytest.raises(ScanFormatError, match="cyclone.pts: .*declares 30 points"):
        read_scan(p)


@pytest.mark.parametrize("rgb", [False, True])
def test_ptx_with_and_without_rgb(tmp_path, rgb):
    head = "1\n3\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n5 6 7 1\n"
    rows = "".join(f"{x} {y} {z} {i}" + (" 255 128 0" if rgb else "") + "\n" for (x, y, z), i in
                   zip(XYZ, (0.2, 0.4, 0.8), strict=False))
    p = tmp_path / "leica.ptx"
    p.write_text(head + rows)
    scan = read_scan(p)
    _check(scan, [0.2, 0.4, 0.8])
    np.testing.assert_allclose(scan.pose[:3, 3], [5, 6, 7])
    assert scan.metadata["intensity_convention"] == "unit float 0-1"


def test_riscan_style_ascii_with_reflectance_db(tmp_path):
    p = tmp_path / "riscan.txt"
    p.write_text("X;Y;Z;Reflectance;Deviation\n" + "".join(f"{x};{y};{z};{r};2\n" for (x, y, z), r in
                                                          zip(XYZ, (-20.0, -3.5, 4.0), strict=False)))
    scan = read_scan(p)
    _check(scan, [-20.0, -3.5, 4.0])
    assert scan.metadata["intensity_convention"] == "Riegl reflectance dB"
    np.testing.assert_allclose(scan.intensity, [0, 16.5 / 24, 1], atol=1e-6)


@pytest.mark.parametrize("version, fmt", [("1.0", 1), ("1.1", 1), ("1.2", 3), ("1.3", 4), ("1.3", 5), ("1.4", 6),
                                          ("1.4", 8), ("1.4", 9), ("1.4", 10)])
def test_las_versions_waveform_formats_and_evlrs(tmp_path, version, fmt):
    header = laspy.LasHeader(point_format=fmt, version="1.1" if version == "1.0" else version)
    header.scales = np.array([1e-4] * 3)
    las = laspy.LasData(header)
    las.x, las.y, las.z = XYZ.T
    las.intensity = np.array([100, 30000, 65535], np.uint16)
    if version == "1.4":
        from laspy.vlrs.vlrlist import VLRList

        las.evlrs = VLRList([laspy.VLR(user_id="other tool", record_id=7, description="evlr",
                                             record_data=b"x" * 300)])
    p = tmp_path / "v.las"
    las.write(p)
    if version == "1.0":  # laspy writes 1.1 at the oldest; 1.0 has the same 227-byte header
        blob = bytearray(p.read_bytes())
        blob[25] = 0
        p.write_bytes(bytes(blob))
    scan = read_scan(p)
    _check(scan, [100, 30000, 65535])
    assert scan.metadata["version"] == version
    assert scan.metadata["intensity_convention"] == "16-bit 0..65535"


def test_e57_with_images_and_no_points_says_so(tmp_path):
    from lidar.io.e57 import write_e57

    p = tmp_path / "s.e57"
    write_e57(sample_scan(20), p)

    def images_only(xml: bytes) -> bytes:
        start, end = xml.index(b"<data3D"), xml.index(b"</data3D>") + len(b"</data3D>")
        return xml[:start] + b'<data3D type="Vector" allowHeterogeneousChildren="1"/>' + \
            b'<images2D type="Vector" allowHeterogeneousChildren="1"><vectorChild type="Structure"/>' + \
            b"</images2D>" + xml[end:]

    q = tmp_path / "images.e57"
    q.write_bytes(e57_with_xml(p.read_bytes(), images_only))
    with pytest.raises(ScanFormatError, match="images.e57: the E57 file holds 1 image.* no point scans"):
        read_scans(q)


def test_e57_with_spherical_coordinates_only(tmp_path):
    import pye57

    r = np.linalg.norm(XYZ, axis=1)
    # pye57 writes cartesian fields only: write the spherical values there and rename the fields in the XML
    data = {"cartesianX": r, "cartesianY": np.arctan2(XYZ[:, 1], XYZ[:, 0]), "cartesianZ": np.arcsin(XYZ[:, 2] / r),
            "intensity": np.array([0.1, 0.2, 0.3])}
    p = tmp_path / "cart.e57"
    e57 = pye57.E57(str(p), mode="w")
    e57.write_scan_raw(data, name="spherical")
    e57.close()

    def spherical(xml: bytes) -> bytes:
        for a, b in ((b"cartesianX", b"sphericalRange"), (b"cartesianY", b"sphericalAzimuth"),
                     (b"cartesianZ", b"sphericalElevation"), (b"cartesianBounds", b"sphericalBounds")):
            xml = xml.replace(a, b)
        return xml

    q = tmp_path / "sph.e57"
    q.write_bytes(e57_with_xml(p.read_bytes(), spherical))
    scan = read_scan(q)
    assert "sphericalRange" in scan.metadata["fields"]
    np.testing.assert_allclose(scan.xyz_socs, XYZ, atol=1e-9)


@pytest.mark.skipif(not PCL, reason="PCL's tools (Debian pcl-tools) are not installed; ./run installs them")
@pytest.mark.parametrize("mode", ["0", "1", "2"])
def test_pcl_reads_our_pcd_and_we_read_pcls(tmp_path, mode):
    scan = sample_scan()
    ours = write_scan(scan, tmp_path / "ours.pcd")
    theirs = tmp_path / f"pcl{mode}.pcd"
    out = subprocess.run(["pcl_convert_pcd_ascii_binary", str(ours), str(theirs), mode, "10"], capture_output=True,
                         text=True, timeout=60)
    assert theirs.exists(), out.stdout + out.stderr
    assert "300 points" in out.stdout + out.stderr  # PCL itself read every point of our file
    back = read_scan(theirs)
    np.testing.assert_allclose(back.xyz_socs, scan.xyz_socs, atol=1e-5 if mode == "0" else 0)
    np.testing.assert_allclose(back.intensity_raw, scan.intensity_raw, rtol=1e-6)
    np.testing.assert_allclose(back.pose, scan.pose, atol=1e-9)


@pytest.mark.skipif(not PCL, reason="PCL's tools (Debian pcl-tools) are not installed; ./run installs them")
def test_pcl_pcd2ply_output_reads_back(tmp_path):
    scan = sample_scan()
    ours = write_scan(scan, tmp_path / "ours.pcd")
    ply = tmp_path / "pcl.ply"
    subprocess.run(["pcl_pcd2ply", str(ours), str(ply)], capture_output=True, timeout=60, check=True)
    back = read_scan(ply)
    np.testing.assert_allclose(back.xyz_socs, scan.xyz_socs)
    np.testing.assert_allclose(back.intensity_raw, scan.intensity_raw)
    pcd = tmp_path / "back.pcd"
    subprocess.run(["pcl_ply2pcd", str(write_scan(scan, tmp_path / "ours.ply")), str(pcd)], capture_output=True,
                   timeout=60, check=True)
    np.testing.assert_allclose(read_scan(pcd).xyz_socs, scan.xyz_socs, atol=1e-6)

"""Whole-scan comparison of two simulated epochs against the simulator's truth, and the compare command."""
from __future__ import annotations

import json
import shutil

import laspy
import numpy as np
import pytest

from app.cli.main import main
from lidar.simulate.files import load_scene
from projects.store.campaign import Campaign
from tests.projects.campaign_helpers import snapshot
from tests.projects.conftest import MODEL


def true_transform(field, k_from: int, k_to: int) -> np.ndarray:
    """SOCS of visit k_from -> SOCS of visit k_to (4x4)."""
    p_from = load_scene(field / f"v{k_from}")[0].pose
    p_to = load_scene(field / f"v{k_to}")[0].pose
    return np.linalg.inv(p_to) @ p_from


@pytest.fixture(scope="module")
def compared(processed, field, tmp_path_factory):
    import shutil

    camp = tmp_path_factory.mktemp("cmp") / "camp"
    shutil.copytree(processed, camp, symlinks=True, ignore=shutil.ignore_patterns(".lock"))
    out = camp.parent / "out"
    assert main(["compare", str(camp), "--from", "2026-03-02", "--to", "2026-03-16", "--out", str(out)]) == 0
    return camp, out


def test_registration_recovers_the_relative_pose_and_icp_keeps_it(compared, field):
    _, out = compared
    s = json.loads((out / "summary.json").read_text())
    reg = s["registration"]["2026-03-16"]
    truth = true_transform(field, 2, 0)
    refs = np.array([t.centre_m for t in MODEL.targets])  # bridge frame -> SOCS of visit 2
    pose2 = load_scene(field / "v2")[0]
    pts = pose2.to_socs(refs)
    tf_targets = np.array(reg["transform"]["matrix"])
    err_icp = np.abs(pts @ tf_targets[:3, :3].T + tf_targets[:3, 3] - (pts @ truth[:3, :3].T + truth[:3, 3])).max()
    assert reg["targets"]["rms_mm"] < 0.5 and not reg["targets"]["warnings"]
    assert err_icp <= 1.0e-3, err_icp  # ICP on the piers and ground: within a millimetre where the bridge is
    assert reg["icp"]["fitness"] > 0.5 and all(i >= 1 for i in reg["icp"]["iterations"])
    d = np.linalg.inv(truth) @ tf_targets
    assert np.degrees(np.arccos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1, 1))) <= 0.005


@pytest.mark.skipif(shutil.which("pcl_ndt3d") is None, reason="PCL's pcl_ndt3d is not installed (pcl-tools)")
def test_ndt_refinement_beside_icp_at_the_targets(processed, field):
    from projects.compare.whole_scan import bring_to_campaign_frame

    truth = true_transform(field, 1, 0)
    pts = load_scene(field / "v1")[0].to_socs(np.array([t.centre_m for t in MODEL.targets]))
    errs = {}
    with Campaign.open(processed, writable=False) as c:
        for refinement in ("ndt", "icp"):
            e = bring_to_campaign_frame(c, "2026-03-09", "2026-03-02", refinement=refinement)
            errs[refinement] = np.abs(e.transform.apply(pts) - (pts @ truth[:3, :3].T + truth[:3, 3])).max()
            assert e.icp.correction.method == refinement
    assert errs["icp"] <= 1.0e-3, errs
    assert errs["ndt"] <= 5.0e-3, errs  # NDT on 1 m cells: millimetres at the targets


def test_target_registration_alone_within_half_a_millimetre(processed, field):
    from projects.compare.whole_scan import bring_to_campaign_frame

    with Campaign.open(processed, writable=False) as c:
        e = bring_to_campaign_frame(c, "2026-03-09", "2026-03-02", refinement="targets")
    truth = true_transform(field, 1, 0)
    pts = load_scene(field / "v1")[0].to_socs(np.array([t.centre_m for t in MODEL.targets]))
    err = np.abs(e.transform.apply(pts) - (pts @ truth[:3, :3].T + truth[:3, 3])).max()
    assert err <= 5e-4, err  # issue 5: <= 0.5 mm with 4 reference targets


def test_m3c2_is_zero_on_the_piers_and_follows_the_deflection_on_the_deck(compared, field):
    _, out = compared
    s = json.loads((out / "summary.json").read_text())
    stable, deck = s["change"]["stable_parts"], s["change"]["deck"]
    assert stable["n"] > 100 and abs(stable["median_mm"]) <= stable["median_lod_mm"]
    las = laspy.read(out / "change.laz")
    xyz = np.column_stack([las.x, las.y, las.z])
    d = np.asarray(las["m3c2_distance_mm"], dtype=float)
    lod = np.asarray(las["lod_mm"], dtype=float)
    # truth at each core point under the deck: 7 mm midspan sag in the first mode
    pose0 = load_scene(field / "v0")[0].pose
    xb = xyz @ pose0[:3, :3].T + pose0[:3, 3]
    under = (np.abs(xb[:, 2] - MODEL.deck_bottom_m) < 0.1) & (xb[:, 0] > 4) & (xb[:, 0] < MODEL.span_m - 4) & \
        np.isfinite(d)
    assert under.sum() > 50
    true_mm = (MODEL.deflection_m(xb[under, 0], -0.007) - MODEL.deflection_m(xb[under, 0], 0.0)) * 1e3
    err = d[under] - true_mm
    assert abs(np.median(err)) < 0.5 and np.mean(np.abs(err) <= lod[under]) >= 0.9
    assert deck["median_mm"] < -3.0 and deck["median_lod_mm"] < 3.0


def test_outputs_profile_and_report_section(compared, tmp_path):
    camp, out = compared
    for name in ("change.laz", "summary.json", "registration.csv", "span_profile.csv", "span_profile.png"):
        assert (out / name).stat().st_size > 0
    s = json.loads((out / "summary.json").read_text())
    bins = s["span_profile"]["bins"]
    assert len(s["span_profile"]["girder_offsets_m"]) == 2
    for g in (1, 2):  # every station from the first pier to the last, on both girder lines
        assert [b["station_m"] for b in bins if b["girder"] == g] == pytest.approx(np.arange(1.25, 40, 2.5))
    for b in bins:  # the 7 mm midspan sag of visit 2, at stations along the layout's x
        truth_mm = (MODEL.deflection_m(b["station_m"], -0.007) - MODEL.deflection_m(b["station_m"], 0.0)) * 1e3
        assert abs(b["change_mm"] - truth_mm) <= max(3 * b["sigma_change_mm"], 0.5), (b, truth_mm)
        assert b["sigma_registration_mm"] > 0
    assert {t["reflector"] for t in s["targets"]} == {"M1", "M2", "M3", "M4", "M5"}
    with Campaign.open(camp, writable=False) as c:
        from projects.compare.whole_scan import comparisons

        assert [x["to"] for x in comparisons(c)] == ["2026-03-16"]
    pdf = tmp_path / "r.pdf"
    assert main(["report", str(camp), "--out", str(pdf)]) == 0
    import subprocess

    text = subprocess.run(["pdftotext", str(pdf), "-"], capture_output=True, text=True).stdout
    assert "Epoch comparison and span profile" in text


@pytest.mark.parametrize("args, message", [
    (["--from", "2026-03-02", "--to", "2026-03-02"], "two different epochs"),
    (["--from", "2026-03-02", "--to", "2099-01-01"], "2099-01-01"),
])
def test_bad_compare_arguments_leave_the_campaign_unchanged(processed_copy, tmp_path, capsys, args, message):
    before = snapshot(processed_copy)
    assert main(["compare", str(processed_copy), *args, "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert snapshot(processed_copy) == before


def test_each_rms_says_what_it_is_computed_on(compared, capsys):
    camp, out = compared
    s = json.loads((out / "summary.json").read_text())
    reg = s["registration"]["2026-03-16"]
    assert "reference targets" in reg["targets"]["rms_on"]
    assert "stable parts" in reg["icp"]["rms_on"] and "stable parts" in reg["icp"]["plane_rms_on"]
    assert reg["icp"]["plane_rms_mm"] < reg["icp"]["rms_mm"]  # the plane distance is the noise, not the voxel
    for part, words in (("stable_parts", "stable parts"), ("deck", "deck underside"), ("all", "everything")):
        assert words in s["change"][part]["computed_on"] and s["change"][part]["rms_mm"] > 0
    from projects.compare.whole_scan import change_lines, registration_lines

    (lab, line), = registration_lines(s)
    assert lab == "2026-03-16" and "on 4 reference targets" in line and "ICP on the stable parts" in line
    assert all(" on " in text for text in change_lines(s))


def test_m3c2_takes_py4dgeo_parameters_and_records_them(processed_copy, tmp_path, capsys):
    from lidar.io import write_scan
    from lidar.scan import Scan

    core = tmp_path / "core.xyz"
    pts = np.column_stack([np.linspace(5, 35, 40), np.full(40, -2.0), np.full(40, 7.0)])
    write_scan(Scan(xyz_socs=pts), core)
    out = tmp_path / "o"
    args = ["compare", str(processed_copy), "--from", "2026-03-02", "--to", "2026-03-09", "--out", str(out),
            "--registration", "targets", "--normal-radii", "0.3", "0.6", "--cyl-radius", "0.3", "--max-distance",
            "0.8", "--corepoints", str(core), "--registration-error", "0.001", "--robust-aggr", "--json"]
    assert main(args) == 0
    p = json.loads(capsys.readouterr().out)["change"]["parameters"]
    assert p["normal_radii"] == [0.3, 0.6] and p["cyl_radius"] == 0.3 and p["max_distance"] == 0.8
    assert p["registration_error"] == 0.001 and p["registration_error_source"] == "given" and p["robust_aggr"]
    assert p["corepoints"] == 40 and str(core) in p["corepoints_from"]
    saved = json.loads((out / "summary.json").read_text())["change"]["parameters"]
    assert saved == p


@pytest.mark.parametrize("extra, words", [
    (["--cyl-radius", "0"], "--cyl-radius must be positive"),
    (["--registration-error", "big"], "--registration-error expects metres"),
    (["--corepoints", "nope.xyz"], "nope.xyz"),
    (["--normal-radii", "-1"], "--normal-radii must be positive"),
])
def test_bad_m3c2_parameters_are_refused_in_one_line_before_computing(processed_copy, tmp_path, capsys, extra, words):
    before = snapshot(processed_copy)
    assert main(["compare", str(processed_copy), "--from", "2026-03-02", "--to", "2026-03-09", "--out",
                 str(tmp_path / "o"), *extra]) == 1
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1
    assert snapshot(processed_copy) == before and not (tmp_path / "o").exists()

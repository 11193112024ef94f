"""The PDF report end to end: sections present, no blank page, scopes, bad input."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from app.cli.main import main
from tests.projects.campaign_helpers import snapshot

pytestmark = pytest.mark.skipif(shutil.which("pdftoppm") is None, reason="needs poppler-utils (./run installs it)")

SECTIONS = ("Displacement survey report", "Summary", "Limits in force", "Reflector layout and target state",
            "Displacement history", "Epochs", "Reference group check", "Processing log", "Scan files", "Action log")


def pages_as_images(pdf, tmp_path, dpi=40):
    from PIL import Image

    subprocess.run(["pdftoppm", "-r", str(dpi), "-gray", str(pdf), str(tmp_path / "pg")], check=True)
    return [np.asarray(Image.open(p)) for p in sorted(tmp_path.glob("pg-*.pgm"), key=lambda p: int(p.stem[3:]))]


def pdf_text(pdf) -> str:
    return subprocess.run(["pdftotext", "-layout", str(pdf), "-"], check=True, capture_output=True, text=True).stdout


def test_whole_campaign_report_has_every_section_and_no_blank_page(processed, tmp_path, capsys):
    out = tmp_path / "report.pdf"
    before = snapshot(processed)
    assert main(["report", str(processed), "--out", str(out), "--author", "A. Surveyor"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert snapshot(processed) == before  # a report never changes the campaign
    text = pdf_text(out)
    for s in SECTIONS:
        assert s in text, s
    for label in ("2026-03-02", "2026-03-09", "2026-03-16"):
        assert f"Epoch {label}" in text
    assert "A. Surveyor" in text and "Riegl VZ-1000" in text and "kr-rail:0-200" in text
    from projects.store.campaign import Campaign

    with Campaign.open(processed, writable=False) as c:
        sha = c.files("2026-03-09")[0].sha256
    assert sha in text.replace(" ", "")  # checksums are printed so results can be traced
    pages = pages_as_images(out, tmp_path)
    assert len(pages) >= 8
    for k, img in enumerate(pages, start=1):
        ink = (img < 200).mean()
        assert ink > 0.01, f"page {k} is blank"


def test_visit_and_period_reports(processed, tmp_path):
    visit = tmp_path / "visit.pdf"
    assert main(["report", str(processed), "--out", str(visit), "--epoch", "2026-03-09"]) == 0
    text = pdf_text(visit)
    assert "Epoch 2026-03-09" in text and "Epoch 2026-03-16" not in text and "Epoch 2026-03-02" not in text
    assert "visit of 2026-03-09" in text
    period = tmp_path / "period.pdf"
    assert main(["report", str(processed), "--out", str(period), "--from", "2026-03-09", "--to", "2026-03-16"]) == 0
    text = pdf_text(period)
    assert "Epoch 2026-03-09" in text and "Epoch 2026-03-16" in text and "Epoch 2026-03-02" not in text


def test_summary_reports_the_largest_movement_and_states(processed):
    from projects.outputs.report import ReportScope, gather
    from projects.store.campaign import Campaign

    with Campaign.open(processed, writable=False) as c:
        content = gather(c, ReportScope())
    rows = [r for r in content.displacements if r["displacement_mm"] is not None]
    assert {r["epoch"] for r in rows} == {"2026-03-02", "2026-03-09", "2026-03-16"}
    biggest = max(rows, key=lambda r: abs(r["displacement_mm"]))
    assert biggest["epoch"] == "2026-03-16" and biggest["displacement_mm"] < -5.0  # the 7 mm midspan sag
    assert all(s.found for s in content.target_states)
    assert all(e.preview is not None for e in content.epochs)


@pytest.mark.parametrize("args, message", [
    (["--epoch", "1999-01-01"], "unknown epoch '1999-01-01'"),
    (["--from", "2026-03-16", "--to", "2026-03-02"], "comes after"),
])
def test_bad_report_arguments(processed, tmp_path, capsys, args, message):
    out = tmp_path / "r.pdf"
    assert main(["report", str(processed), "--out", str(out), *args]) == 1
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob(".*part*"))


def test_bad_output_paths(processed, tmp_path, capsys):
    for out, message in ((tmp_path / "r.txt", "ending in .pdf"), (tmp_path / "nowhere" / "r.pdf", "does not exist")):
        assert main(["report", str(processed), "--out", str(out)]) == 1
        assert message in capsys.readouterr().err
    assert main(["report", str(tmp_path / "none"), "--out", str(tmp_path / "r.pdf")]) == 1
    assert "no campaign here" in capsys.readouterr().err


def test_map_preview_round_trip(processed):
    from projects.store.campaign import Campaign

    with Campaign.open(processed, writable=False) as c:
        p = c.map_preview("2026-03-02")
        plan = c.plan("2026-03-02")
    assert p.reflectance_map.count.size <= 1_000_000 and p.reflectance_map.n_points > 100_000
    ids = {m.id for m in p.identification.matches}
    assert {"R1", "R2", "R3", "R4", "M1", "M5"} <= ids
    assert len(p.detections.detections) >= 8 and plan is not None
    # detections sit on bright cells of the stored map
    for d in p.detections.detections[:5]:
        r, col = p.reflectance_map.cells_of(d.theta_deg, d.phi_deg)
        r, col = int(round(float(r))), int(round(float(col)))
        patch = p.reflectance_map.max_intensity[max(r - 2, 0):r + 3, max(col - 2, 0):col + 3]
        assert np.nanmax(patch) > 0.5

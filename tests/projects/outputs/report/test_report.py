"""The PDF report end to end: sections present, no blank page, scopes, bad input."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from app.cli.main import main
from tests.projects.campaign_helpers import snapshot

pytestmark = pytest.mark.skipif(shutil.which("pdftoppm") is None, reason="needs poppler-utils (./run installs it)")

#: The main body's sections, and the appendix's (``--detail``).
BODY = ("Displacement survey report", "Summary", "Limits in force", "attention",
        "Reflector layout and target state", "Displacement history", "Field error budget")
SECTIONS = BODY + ("Appendix A: every visit", "Reference group check", "Appendix B: the field model by visit",
                   "Appendix C: processing log", "Scan files", "Action log")


def pages_as_images(pdf, tmp_path, dpi=40):
    from PIL import Image

    subprocess.run(["pdftoppm", "-r", str(dpi), "-gray", str(pdf), str(tmp_path / "pg")], check=True)
    return [np.asarray(Image.open(p)) for p in sorted(tmp_path.glob("pg-*.pgm"), key=lambda p: int(p.stem[3:]))]


def pdf_text(pdf) -> str:
    return subprocess.run(["pdftotext", "-layout", str(pdf), "-"], check=True, capture_output=True, text=True).stdout


def test_whole_campaign_report_has_every_section_and_no_blank_page(processed, tmp_path, capsys):
    out = tmp_path / "report.pdf"
    before = snapshot(processed)
    assert main(["report", str(processed), "--out", str(out), "--author", "A. Surveyor", "--detail"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert snapshot(processed) == before  # a report never changes the campaign
    text = pdf_text(out)
    for s in SECTIONS:
        assert s in text, s
    for label in ("2026-03-02", "2026-03-09", "2026-03-16"):
        assert f"Epoch {label}" in text
    # the field error budget page, and each epoch says what its displacements were corrected for
    assert "Field error budget" in text and "Each visit's corrections" in text and "Range walk:" in text
    assert "axis errors the data support:" in " ".join(text.split())  # the fitted ones, or "none"
    assert text.count("Corrected for: scale") == 3 and "scale 0 ppm (the baseline defines it)" in text
    assert "1970" not in text  # an empty drift panel keeps no time axis
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


def test_the_main_body_speaks_words_and_the_appendix_is_asked_for(processed, tmp_path):
    """Without --detail: the body's sections, no flag code anywhere, the visits that need attention only, and a
    line saying where the detail is (issue 38: a report a bridge owner reads)."""
    from common.flags import REGISTRY

    out = tmp_path / "body.pdf"
    assert main(["report", str(processed), "--out", str(out)]) == 0
    text = pdf_text(out)
    flat = " ".join(text.split())
    for s in BODY:
        assert s in text, s
    assert "Appendix A" not in text and "Action log" not in text and "--detail" in flat
    codes = [c for c in REGISTRY if "_" in c and c in flat]
    assert not codes, f"flag codes in the report's body: {codes}"
    detail = tmp_path / "detail.pdf"
    assert main(["report", str(processed), "--out", str(detail), "--detail"]) == 0
    assert len(pages_as_images(out, tmp_path)) < len(pages_as_images(detail, tmp_path / ".."))


def test_visit_and_period_reports(processed, tmp_path):
    visit = tmp_path / "visit.pdf"
    assert main(["report", str(processed), "--out", str(visit), "--epoch", "2026-03-09", "--detail"]) == 0
    text = pdf_text(visit)
    assert "Epoch 2026-03-09" in text and "Epoch 2026-03-16" not in text and "Epoch 2026-03-02" not in text
    assert "visit of 2026-03-09" in text
    period = tmp_path / "period.pdf"
    assert main(["report", str(processed), "--out", str(period), "--from", "2026-03-09", "--to", "2026-03-16",
                 "--detail"]) == 0
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


def _cell_words_broken(flowables) -> list[str]:
    """Words a table cell breaks inside (reportlab splits a word that does not fit its column)."""
    import html
    import re

    from reportlab.platypus import Paragraph, Table

    from projects.outputs.report.flowables import CELL_PADDING_PT

    broken = []
    for t in flowables:
        if not isinstance(t, Table):
            continue
        for row in t._cellvalues:
            for w, cell in zip(t._colWidths, row, strict=False):
                if not isinstance(cell, Paragraph):
                    continue
                cell.wrap(w - 2 * CELL_PADDING_PT, 10_000)
                source = set(html.unescape(re.sub(r"<[^>]+>", " ", cell.text)).split())
                bl = cell.blPara
                lines = [" ".join(x[1]) for x in bl.lines] if bl.kind == 0 else \
                    ["".join(f.text for f in x.words) for x in bl.lines]
                broken += [word for line in lines for word in line.split() if word not in source]
    return broken


def test_tables_never_break_a_word_and_numbers_are_rounded(processed):
    from projects.outputs.report import ReportScope, gather
    from projects.outputs.report.flowables import cell_paragraph, styles
    from projects.outputs.report.pdf import epoch_section, layout_section, log_section, summary_section
    from projects.store.campaign import Campaign

    ss = styles()
    with Campaign.open(processed, writable=False) as c:
        content = gather(c, ReportScope(), with_previews=False)
    story = summary_section(content, ss) + layout_section(content, ss) + log_section(content, ss)
    for e in content.epochs:
        story += epoch_section(e, content, ss)
    assert _cell_words_broken(story) == []
    p = cell_paragraph("displacements computed", 20 * 2.83465, ss["Cell"])  # 20 mm: the old action column
    assert p.style.fontSize < ss["Cell"].fontSize and _cell_words_broken([_one_cell_table(p, 20)]) == []
    from projects.outputs.report.flowables import num

    assert num(-0.0037, "{:+.2f}") == "+0.00" and num(-0.004) == "0.00" and num(-0.05) == "-0.05"


def _one_cell_table(p, width_mm):
    from reportlab.lib.units import mm
    from reportlab.platypus import Table

    return Table([[p]], colWidths=[width_mm * mm])


def test_the_report_reads_like_a_professionals(processed_copy, field, tmp_path):
    """Issue 25.8: states as 'status' gives them, limits to 0.1 mm, an action log in words, hints in the
    application's and the command line's words."""
    import dataclasses

    from projects.outputs.report import ReportScope, gather
    from projects.outputs.report.flowables import styles
    from projects.outputs.report.pdf import summary_section
    from projects.results.state import epoch_state
    from projects.store.campaign import Campaign

    las = tmp_path / "coarse-again.las"  # the first visit's scan once more, as another file
    assert main(["convert", str(field / "v0" / "coarse.laz"), str(las)]) == 0
    with Campaign.open(processed_copy) as c:
        c.add_epoch("2026-03-23", "2026-03-23T09:00:00+00:00", las)
    out = tmp_path / "r.pdf"
    assert main(["report", str(processed_copy), "--out", str(out), "--detail"]) == 0
    text = pdf_text(out)
    with Campaign.open(processed_copy, writable=False) as c:
        states = {e.label: epoch_state(c, e.label)[0] for e in c.epochs()}
        content = gather(c, ReportScope(), with_previews=False)
    assert states["2026-03-23"] == "imported" and states["2026-03-16"] == "processed"
    for label, state in states.items():
        page = text.split(f"Epoch {label} — ")[1][:200]
        assert f"State: {state}." in page or f"State: {state} (" in page, (label, page)
    assert "State: measured" not in text
    assert "16.8" in text and "21.1" in text and "16.84" not in text and "21.05" not in text
    log = text.split("Action log")[1]
    assert "coarse scan imported" in log and "displacements computed" in log and "limit set" in log
    assert '{"' not in log and "sha256" not in log
    empty = dataclasses.replace(content, limits=())
    hint = " ".join(p.getPlainText() for p in summary_section(empty, styles()) if hasattr(p, "getPlainText"))
    assert "Campaign ▸ Set limit…" in hint and "bridgesurvey limit DIR --rule" in hint


def test_thin_cross_validation_and_the_analysis_page(processed, tmp_path):
    """A one-row camera series gives no statistics; the analysis page has a figure per target and says what a
    negative creep coefficient means."""
    import dataclasses

    from reportlab.graphics.shapes import Drawing

    from common.series import Series
    from projects.outputs.report import ReportScope, gather
    from projects.outputs.report.analysis_page import analysis_section
    from projects.outputs.report.flowables import styles
    from projects.outputs.report.pdf import build_pdf, crossval_section
    from projects.store.campaign import Campaign
    from projects.store.history import histories
    from tests.projects.analysis.test_run import _doc
    from vision.crossval import cross_validate

    with Campaign.open(processed, writable=False) as c:
        content = gather(c, ReportScope(), with_previews=False)
        h = histories(c)["M3"]
    one = Series(unit="mm", time_ns=h.time_ns[1:2] + 60 * 10**9, values=np.array([2.0]))
    cv = cross_validate(list(h.epochs), h.time_ns, h.displacement_mm, h.sigma_mm, one, reflector="M3", series="one")
    doc, _, _ = _doc()
    content = dataclasses.replace(content, extras={**content.extras, "crossvals": [(cv.to_json(), one)],
                                                   "analysis": doc})
    ss = styles()
    words = " ".join(p.getPlainText() for p in crossval_section(content, ss) if hasattr(p, "getPlainText"))
    assert "Only 1 pair: too few for statistics (5 needed)" in words
    page = analysis_section(content, ss)
    flat = [f for x in page for f in getattr(x, "_content", [x])]
    assert sum(isinstance(f, Drawing) for f in flat) == len(doc["targets"])
    assert _cell_words_broken(flat) == []
    out = build_pdf(content, tmp_path / "r.pdf")
    text = pdf_text(out)
    assert "RMSE 0.000" not in text and "100 %" not in text.split("Cross-check")[1].split("Analysis")[0]
    assert "Target M3" in text, text
    assert "recovery" in text

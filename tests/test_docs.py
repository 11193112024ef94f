"""The user guide: a short README whose links work, the documentation site built strictly, the benches' tables.

The site (mkdocs.yml) is built here with MkDocs in strict mode, so './run test' fails on a broken link or
anchor between pages, a bench table a page includes but nobody wrote, or a docstring the API reference
cannot read.
"""
from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
from markdown.extensions.toc import slugify

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
#: [text](target) and ![alt](target), outside code spans (the README has no link inside one)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
HEADING = re.compile(r"^#{1,6} +(.+?) *$", re.MULTILINE)
INCLUDE = re.compile(r'^--8<-- "figures/([a-z0-9_]+)\.md"$', re.MULTILINE)
WRITES = re.compile(r'write_figure\(\s*"([a-z0-9_]+)"')


def _anchors(markdown_file: Path) -> set[str]:
    """The anchors MkDocs gives the headings of a Markdown file (its table-of-contents slugs)."""
    text = re.sub(r"^```.*?^```", "", markdown_file.read_text(encoding="utf-8"), flags=re.MULTILINE | re.DOTALL)
    return {slugify(re.sub(r"[`*]", "", h), "-") for h in HEADING.findall(text)}


def _outside_code(text: str) -> str:
    text = re.sub(r"^```.*?^```", "", text, flags=re.MULTILINE | re.DOTALL)
    return re.sub(r"`[^`\n]*`", "", text)


def test_readme_is_a_five_minute_read():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 300, f"README.md has {len(lines)} lines: move the detail into docs/ (at most 300)"


def test_readme_relative_links_resolve():
    links = LINK.findall(_outside_code(README.read_text(encoding="utf-8")))
    relative = [t for t in links if not re.match(r"[a-z]+:", t)]
    assert any(t.startswith("docs/") for t in relative), "the README links into the user guide"
    broken = []
    for target in relative:
        path_part, _, anchor = target.partition("#")
        path = (ROOT / path_part).resolve() if path_part else README
        if not path.exists() or (ROOT not in path.parents and path != ROOT):
            broken.append(f"{target}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
            broken.append(f"{target}: no heading with that anchor in {path.relative_to(ROOT)}")
    assert not broken, "README.md links that do not resolve:\n" + "\n".join(broken)


def test_anchor_slugs_are_mkdocs_own():
    """The link check above slugs headings as MkDocs does ('Two commands' -> 'two-commands')."""
    assert slugify("Layout of the code", "-") == "layout-of-the-code"
    assert slugify("layout.csv", "-") == "layoutcsv"


def test_every_bench_table_is_seeded_and_shown():
    """Each table a bench writes (bench/_harness.py write_figure) exists in docs/figures and a page includes it."""
    written = {name for f in (ROOT / "bench").glob("*.py") for name in WRITES.findall(f.read_text(encoding="utf-8"))}
    assert {"peers", "field_effects", "long_bridges", "normal_geometry"} <= written
    seeded = {p.stem for p in (DOCS / "figures").glob("*.md")}
    included = {name for page in DOCS.rglob("*.md") for name in INCLUDE.findall(page.read_text(encoding="utf-8"))}
    assert written - seeded == set(), "benches whose table has no file in docs/figures"
    assert seeded - written == set(), "tables in docs/figures that no bench writes (typed by hand?)"
    assert seeded - included == set(), "tables in docs/figures that no page includes"


def _harness():
    spec = importlib.util.spec_from_file_location("bench_harness", ROOT / "bench" / "_harness.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_write_figure_records_date_command_and_machine(tmp_path, monkeypatch):
    harness = _harness()
    monkeypatch.setattr(harness, "FIGURES", tmp_path / "figures")
    path = harness.write_figure("demo_table", "| a | b |\n|---|---|\n| 1 | 2 |\n", notes="¹ a note",
                                argv=["--visits", "3"])
    assert path == tmp_path / "figures" / "demo_table.md"
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("<!--") and lines[0].endswith("-->")
    assert re.fullmatch(r"\*Measured \d{4}-\d\d-\d\d \d\d:\d\d UTC by `\./run bench demo_table --visits 3` "
                        r"on .+, \d+ cores.*, Python 3\.\d+\.\d+, numpy \d.*\.\*", lines[1]), lines[1]
    assert lines[2:] == ["", "| a | b |", "|---|---|", "| 1 | 2 |", "", "¹ a note"]


@pytest.mark.slow
def test_docs_site_builds_strictly(tmp_path):
    site = tmp_path / "site"
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                         cwd=ROOT, capture_output=True, text=True)
    problems = [ln for ln in res.stderr.splitlines() if not ln.startswith("INFO")]
    assert res.returncode == 0, "the documentation does not build (./run docs):\n" + "\n".join(problems[-30:])
    assert problems == [], "\n".join(problems)
    # the API reference is generated from the docstrings, and the benches' tables are in their pages
    assert "compute_displacements" in (site / "api" / "lidar.html").read_text(encoding="utf-8")
    assert "<th>ratio / verdict</th>" in (site / "accuracy-speed.html").read_text(encoding="utf-8")

"""Building blocks of the report's pages (reportlab): fonts, styles, cells, numbers and figures.

Table cells never break a word; numbers that round to zero print without a minus sign; matplotlib
figures go in as vector drawings. The report, the field sheet and the fleet summary share them.
"""
from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import numpy as np
from matplotlib import get_data_path
from reportlab.lib import colors
from reportlab.lib.fonts import addMapping
from reportlab.lib.styles import ParagraphStyle, getSampleStyleSheet
from reportlab.lib.units import mm
from reportlab.pdfbase import pdfmetrics
from reportlab.pdfbase.pdfmetrics import stringWidth
from reportlab.pdfbase.ttfonts import TTFont
from reportlab.platypus import Paragraph, Table, TableStyle
from svglib.svglib import svg2rlg


def fonts() -> tuple[str, str]:
    """DejaVu Sans (shipped with matplotlib) so that σ, ±, ≤ print; registered once."""
    if "DejaVuSans" not in pdfmetrics.getRegisteredFontNames():
        ttf = Path(get_data_path()) / "fonts" / "ttf"
        pdfmetrics.registerFont(TTFont("DejaVuSans", str(ttf / "DejaVuSans.ttf")))
        pdfmetrics.registerFont(TTFont("DejaVuSans-Bold", str(ttf / "DejaVuSans-Bold.ttf")))

        addMapping("DejaVuSans", 0, 0, "DejaVuSans")
        addMapping("DejaVuSans", 1, 0, "DejaVuSans-Bold")
    return "DejaVuSans", "DejaVuSans-Bold"


def styles() -> Any:
    """The report's paragraph styles (DejaVu Sans; ``Cell`` for table cells, ``Small``, ``Mono``...)."""
    regular, bold = fonts()
    ss = getSampleStyleSheet()
    for name in ("Normal", "BodyText", "Title", "Heading1", "Heading2", "Heading3"):
        ss[name].fontName = bold if name != "Normal" and name != "BodyText" else regular
    ss["Normal"].fontSize = 9
    ss["Normal"].leading = 12
    ss.add(ParagraphStyle("Small", parent=ss["Normal"], fontSize=7.5, leading=9.5))
    ss.add(ParagraphStyle("Cell", parent=ss["Normal"], fontSize=7, leading=8.5))
    ss.add(ParagraphStyle("Mono", parent=ss["Normal"], fontName="Courier", fontSize=5.8, leading=8))
    ss.add(ParagraphStyle("Big", parent=ss["Title"], fontSize=24, leading=30, alignment=0))
    ss.add(ParagraphStyle("Sub", parent=ss["Normal"], fontSize=13, leading=17))
    ss["Heading1"].fontSize = 15
    ss["Heading2"].fontSize = 11.5
    ss["Heading2"].spaceBefore = 8
    ss["Heading3"].fontSize = 9.5
    ss["Heading3"].spaceBefore = 4
    ss["Heading3"].spaceAfter = 2
    return ss


def esc(text: Any) -> str:
    """Text escaped for a reportlab Paragraph (None as empty)."""
    return escape("" if text is None else str(text))


def num(v: Any, fmt: str = "{:.2f}") -> str:
    """A number as text, ``–`` for none; a value that rounds to zero prints without a minus sign."""
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    text = fmt.format(v)
    return fmt.format(0.0) if text.lstrip("+-−").strip("0.") == "" and text[:1] in "-−" else text


#: Cell padding of every table (points, each side), and the smallest font a cell shrinks to so that no
#: word is broken inside.
CELL_PADDING_PT = 3.0
MIN_CELL_FONT_PT = 5.0


def cell_paragraph(text: str | Sequence[str], width_pt: float, style: Any) -> Any:
    """A table cell's Paragraph: words wrap between them, never inside one; a sequence of texts gives one line each.

    When the longest word does not fit the column, the cell's font shrinks until it does (down to
    :data:`MIN_CELL_FONT_PT`; only a longer unbreakable string, a checksum, may still be split).
    """
    lines = [text] if isinstance(text, str) else list(text)
    avail = width_pt - 2 * CELL_PADDING_PT
    words = [w for line in lines for w in str(line).split()]
    longest = max((stringWidth(w, style.fontName, style.fontSize) for w in words), default=0.0)
    if longest > avail > 0:
        size = max(MIN_CELL_FONT_PT, style.fontSize * avail / longest * 0.98)
        style = ParagraphStyle(f"{style.name}-{size:.2f}", parent=style, fontSize=size, leading=size * 1.2)
    return Paragraph("<br/>".join(esc(line) for line in lines), style)


def _is_text(c: Any) -> bool:
    return isinstance(c, str) or (isinstance(c, (list, tuple)) and all(isinstance(x, str) for x in c))


def table(rows: Sequence[Sequence], widths_mm: Sequence[float], ss: Any, *, header_rows: int = 1,
          cell_colours: Sequence[tuple[int, int, str]] = ()) -> Any:
    """A grid table: text cells (a str, or a list of lines) as :func:`cell_paragraph`, header rows shaded."""
    data = [[cell_paragraph(c, widths_mm[j] * mm, ss["Cell"]) if _is_text(c) else c for j, c in enumerate(r)]
            for r in rows]
    t = Table(data, colWidths=[w * mm for w in widths_mm], repeatRows=header_rows)
    style = [("GRID", (0, 0), (-1, -1), 0.25, colors.HexColor("#9e9e9e")),
             ("BACKGROUND", (0, 0), (-1, header_rows - 1), colors.HexColor("#e3eaf3")),
             ("VALIGN", (0, 0), (-1, -1), "TOP"),
             ("LEFTPADDING", (0, 0), (-1, -1), CELL_PADDING_PT), ("RIGHTPADDING", (0, 0), (-1, -1), CELL_PADDING_PT),
             ("TOPPADDING", (0, 0), (-1, -1), 1.5), ("BOTTOMPADDING", (0, 0), (-1, -1), 1.5)]
    for r in range(header_rows, len(rows)):
        if (r - header_rows) % 2:
            style.append(("BACKGROUND", (0, r), (-1, r), colors.HexColor("#f6f6f6")))
    for r, c, colour in cell_colours:
        style.append(("BACKGROUND", (c, r), (c, r), colors.HexColor(colour)))
    t.setStyle(TableStyle(style))
    return t


def figure_flowable(fig: Any, width_mm: float) -> Any:
    """A matplotlib Figure as a vector drawing ``width_mm`` wide (SVG through svglib).

    Maps are raster images instead: see :func:`render_map_jpeg`.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="svg")
    buf.seek(0)
    d = svg2rlg(buf)
    if d is None:
        raise ValueError("matplotlib wrote an SVG that svglib cannot read")
    f = width_mm * mm / d.width
    d.scale(f, f)
    d.width, d.height = d.width * f, d.height * f
    return d



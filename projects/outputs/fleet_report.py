"""The fleet summary PDF: an overview, then one line per bridge."""
from __future__ import annotations

import datetime as dt
import os
from pathlib import Path

from reportlab.lib.units import mm
from reportlab.platypus import Paragraph, Spacer

from projects.outputs.report.flowables import esc, num, styles, table
from projects.outputs.report.pdf import write_landscape_pdf

STATE_COLOURS = {"ok": "#c8e6c9", "warning": "#ffe0b2", "alarm": "#ffcdd2", "unknown": "#eeeeee"}


def write_fleet_report(status: dict, path: str | os.PathLike, *, title: str = "Bridge fleet") -> Path:
    """Write :func:`projects.fleet.fleet_status` output as a PDF."""
    ss = styles()
    ov = status["overview"]
    story = [Paragraph(esc(f"{title}: {ov['bridges']} bridges"), ss["Heading1"]),
             Paragraph(esc(f"Written {dt.datetime.now().strftime('%Y-%m-%d %H:%M')}. In alarm: {ov['alarm']}; "
                            f"warning: {ov['warning']}; ok: {ov['ok']}; no limit or no displacement yet: "
                            f"{ov['unknown']}; unreadable: {ov['unreadable']}. Epochs with work left: "
                            f"{ov['work_left']}."), ss["Normal"])]
    if ov["overdue"]:
        story.append(Paragraph(esc(f"Overdue (no visit for more than {ov['overdue_days']} days): "
                                    + ", ".join(ov["overdue"])), ss["Normal"]))
    root = _common_root([b["folder"] for b in status["bridges"]])
    if root:
        story.append(Paragraph(esc(f"Folders are under {root}."), ss["Normal"]))
    story.append(Spacer(1, 4 * mm))
    rows = [["Bridge", "State", "Worst target", "Displacement (mm)", "Alarm limit (mm)", "Last epoch",
             "Days since", "Work left", "Problems", "Cross-validation", "Folder"]]
    colours = []
    for k, b in enumerate(status["bridges"], start=1):
        cv = "; ".join(f"{x['series']}: RMSE {num(x.get('rmse_mm'))} mm" for x in b["crossval"]) or "–"
        if b["error"]:
            rows.append([b["name"], "unreadable", "–", "–", "–", "–", "–", "–", "–", "–", f"{_short(b['folder'], root)}: {b['error']}"])
            colours.append((k, 1, STATE_COLOURS["unknown"]))
            continue
        rows.append([b["name"], b["state"], b["worst_target"] or "–", num(b["worst_displacement_mm"]),
                     num(b["worst_limit_mm"]), f"{b['last_epoch'] or '–'} {b['last_date'] or ''}",
                     "–" if b["days_since"] is None else str(b["days_since"]), str(b["work_left"]),
                     str(b["problems"]), cv, _short(b["folder"], root)])
        colours.append((k, 1, STATE_COLOURS.get(b["state"], "#eeeeee")))
    story.append(table(rows, [38, 18, 18, 22, 20, 34, 14, 14, 15, 40, 44], ss, cell_colours=colours))
    return write_landscape_pdf(story, path, title=title)


def _common_root(folders: list[str]) -> str:
    """The folder all bridges share (so that the table shows short names that do not wrap), or ''."""
    parents = [str(Path(f).parent) for f in folders]
    if not parents:
        return ""
    try:
        return os.path.commonpath(parents)
    except ValueError:  # different drives
        return ""


def _short(folder: str, root: str) -> str:
    return os.path.relpath(folder, root) if root else folder

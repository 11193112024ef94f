"""The report's analysis section: a summary table, then per target its figure and its events in words.

Numbers are rounded to what they mean: thermal coefficients to 0.01 mm/°C, steps and creep to 0.01 mm,
creep coefficients to 0.01, trends and offsets to 0.1 mm, limits to 0.1 mm (see ``analysis.json`` for
every digit).
"""
from __future__ import annotations

from typing import Any

from reportlab.platypus import KeepTogether, PageBreak, Paragraph, Spacer

from projects.analysis.figures import along_figure, target_figure
from projects.outputs.report.content import ReportContent
from projects.outputs.report.flowables import esc, figure_flowable, num, table

FIGURE_SIZE_IN = (7.0, 3.5)


def _pm(v: float | None, s: float | None, fmt: str = "{:+.2f}", sfmt: str = "{:.2f}") -> str:
    if v is None:
        return "–"
    return num(v, fmt) + ("" if s is None else " ± " + num(s, sfmt))


def _projection(t: dict) -> list[str]:
    """The projection at the horizon and when the warning level is reached, one line each."""
    proj = t.get("projection") or {}
    if not proj:
        return ["–"]
    out = [f"{_pm(proj.get('displacement_mm'), proj.get('sigma_mm'))} mm on {proj.get('date')}"]
    if proj.get("warning_earliest"):
        out.append(f"warning level on {proj.get('warning_date') or '–'} (2σ: from {proj['warning_earliest']})")
    elif proj.get("warning"):
        out.append("warning level not within 10 years")
    return out


def summary_rows(doc: dict) -> list[list]:
    """One row per target: thermal coefficient, trend, seasonal amplitude, steps, creep, prediction, projection."""
    rows: list[list] = [["Target", "Thermal [mm/°C]", "Trend [mm/yr]", "Seasonal [mm]", "Steps [mm]",
                         "Creep coefficient", "Design prediction offset / RMS [mm]", "Projection"]]
    for t in doc["targets"]:
        steps = [f"{k}: {_pm(e['step_mm'], e['step_sigma_mm'])}" for k, e in _numbered(doc, t)] or ["–"]
        creep = [f"{k}: {_pm(e['creep_coefficient'], e['creep_coefficient_sigma'], '{:.2f}')}"
                 + (" *" if e["note"] else "") for k, e in _numbered(doc, t)] or ["–"]
        rows.append([t["reflector"], _pm(t["thermal_mm_per_degC"], t["thermal_sigma"]),
                     _pm(t["trend_mm_per_year"], t["trend_sigma"], "{:+.1f}", "{:.1f}"),
                     num(t["seasonal_amplitude_mm"], "{:.1f}"), steps, creep,
                     f"{num(t['prediction_offset_mm'], '{:+.1f}')} / {num(t['prediction_residual_rms_mm'], '{:.2f}')}",
                     _projection(t)])
    return rows


def _numbered(doc: dict, target: dict) -> list[tuple[int, dict]]:
    """The target's events with the number the figures give them (their order among the campaign's events)."""
    order = {(e["date"][:10], e["label"]): k for k, e in enumerate(doc["events"], start=1)}
    return [(order.get((e["date"][:10], e["label"]), 0), e) for e in target["events"]]


def event_rows(doc: dict, target: dict) -> list[list[str]]:
    """The target's events: date, step, creep developed by the last epoch, creep coefficient and what it means."""
    rows = [["", "Event", "Date", "Step [mm]", "Creep by the last epoch [mm]", "Creep coefficient", "Note"]]
    for k, e in _numbered(doc, target):
        rows.append([str(k), e["label"], e["date"][:10], _pm(e["step_mm"], e["step_sigma_mm"]),
                     _pm(e["creep_mm"], e["creep_sigma_mm"]),
                     _pm(e["creep_coefficient"], e["creep_coefficient_sigma"], "{:.2f}"), e["note"] or "–"])
    return rows


def _target_text(t: dict) -> str:
    parts = [f"{t['epochs']} epochs, residual RMS {num(t['rms_residual_mm'])} mm"]
    if t["thermal_mm_per_degC"] is not None:
        parts.append(f"temperature averaged over {t['temperature_window_h']:g} h ending {t['temperature_lag_h']:g} h "
                     f"before each scan, corrected to {num(t['reference_temperature_degC'], '{:.1f}')} °C"
                     + ("" if t["thermal_significant"] else " (thermal coefficient not significant, p ≥ 0.05)"))
    if t.get("along_mm_per_degC") is not None:
        parts.append(f"along the span {_pm(t['along_mm_per_degC'], t['along_sigma'], '{:+.3f}', '{:.3f}')} mm/°C "
                     f"over {t['along_epochs']} epochs")
    if t.get("along_note"):
        parts.append(t["along_note"])
    if t.get("creep_law"):
        law, p = t["creep_law"].split(":")
        parts.append(("ACI 209 creep shape" if law == "aci" else "exponential creep") + f", time parameter {p} d")
    return "; ".join(parts) + "."


def analysis_section(content: ReportContent, ss: Any) -> list:
    """What explains the displacements: temperature effect, events with creep, trend and projection, per target."""
    doc = content.extras["analysis"]
    intro = (f"Each target's history fitted by weighted least squares: a thermal coefficient, each event's "
             f"immediate step and the creep after it, a trend when the data want one. Temperature: "
             f"{doc['temperature_source'] or 'none imported'}; baseline {doc['baseline']}"
             + (f"; concrete cast {doc['casting_date'][:10]}" if doc.get("casting_date") else "")
             + ". Values are ± one standard deviation; the creep coefficient is the creep developed by the last "
               "epoch over the step (* : see the note under the target's figure).")
    if any(t.get("prediction_offset_mm") is not None for t in doc["targets"]):
        intro += (" Design prediction: the offset is the constant added to the design model's curve so that it "
                  "meets the measurements (at the alignment date, or by least squares over every visit); the RMS is "
                  "how far the measurements stay from the aligned curve. The aligned curve is drawn dashed in each "
                  "target's figure.")
    out = [PageBreak(), Paragraph("Analysis: temperature, events, creep and projection", ss["Heading1"]),
           Paragraph(esc(intro), ss["Small"])]
    for w in doc["warnings"]:
        out.append(Paragraph(esc(f"⚠ {w}"), ss["Small"]))
    out += [Spacer(1, 4), table(summary_rows(doc), (13, 22, 17, 15, 27, 25, 22, 37), ss), Spacer(1, 6)]
    for t in doc["targets"]:
        fig = target_figure(doc, t, figsize=FIGURE_SIZE_IN)
        block = [Paragraph(esc(f"Target {t['reflector']}"), ss["Heading3"]),
                 figure_flowable(fig, 170), Paragraph(esc(_target_text(t)), ss["Small"])]
        if t.get("along_points"):
            block.append(figure_flowable(along_figure(t), 80))
        if t["events"]:
            block += [Spacer(1, 2), table(event_rows(doc, t), (6, 34, 18, 22, 26, 22, 50), ss)]
        block += [Paragraph(esc(n), ss["Small"]) for n in t["notes"]]
        out += [KeepTogether(block), Spacer(1, 8)]
    return out

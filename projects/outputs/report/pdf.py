"""The survey report as a PDF (reportlab platypus; figures from matplotlib, line plots as vectors)."""
from __future__ import annotations

import io
import multiprocessing
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, wait
from pathlib import Path
from typing import Any

import numpy as np
from reportlab import rl_config
from reportlab.lib.pagesizes import A4, landscape
from reportlab.lib.units import mm
from reportlab.platypus import (
    BaseDocTemplate,
    Frame,
    Image,
    NextPageTemplate,
    PageBreak,
    PageTemplate,
    Paragraph,
    SimpleDocTemplate,
    Spacer,
)

from common.files import atomic_output
from common.flags import FLAG_NO_CAMERA_DATA, REGISTRY, code, describe, first_action, severity, summary
from common.progress import ProgressCallback, report, scaled
from lidar.reflectance_map import reduce_map
from lidar.setups import join_summary, join_tables
from projects.compare.figures import span_profile_figure
from projects.compare.whole_scan import registration_lines
from projects.outputs.figures import displacement_history_figure
from projects.outputs.report.action_log import action_row
from projects.outputs.report.analysis_page import analysis_section
from projects.outputs.report.content import EpochSection, ReportContent
from projects.outputs.report.field_page import field_appendix, field_section
from projects.outputs.report.flowables import esc, figure_flowable, fonts, num, styles, table
from projects.outputs.report.plots import epoch_map_figure, history_grid_figure, layout_figure
from projects.results.corrections import corrections_line
from projects.series.context import WHOLE_DAY_COVERAGE
from projects.store.previews import MapPreview
from vision.crossval import CrossValidation
from vision.figures import difference_figure, overlay_figure, scatter_figure

PAGE_MARGIN_MM = 16
#: The states of a visit that needs the reader's attention (its page in the main body).
ATTENTION_STATES = ("warning", "problem")
STATE_COLOURS = {"ok": "#c8e6c9", "warning": "#ffe0b2", "alarm": "#ffcdd2", "unknown": "#eeeeee"}


# ----------------------------------------------------------------------------- styles and helpers
# (kept under their old names: the field sheet and the fleet report use them too)
_fonts, _styles, _esc, _num, _table = fonts, styles, esc, num, table


def write_landscape_pdf(story: list, path: str | os.PathLike, *, title: str) -> Path:
    """A one-off landscape A4 document (field sheet, fleet summary), written through a temporary file."""
    with atomic_output(path) as tmp:
        SimpleDocTemplate(str(tmp), pagesize=landscape(A4), leftMargin=10 * mm, rightMargin=10 * mm,
                          topMargin=10 * mm, bottomMargin=10 * mm, title=title).build(story)
    return Path(path)


def _make_doc(path, content: ReportContent):
    """A BaseDocTemplate with header and footer, whose level-1/2 headings become PDF bookmarks."""
    rl_config.useA85 = 0  # binary streams: ASCII85 is slow in pure Python and makes files larger
    regular, _ = _fonts()

    class Doc(BaseDocTemplate):
        def afterFlowable(self, flowable):
            style = getattr(flowable, "style", None)
            if style is not None and style.name in ("Heading1", "Heading2"):
                key = f"h{id(flowable)}"
                self.canv.bookmarkPage(key)
                self.canv.addOutlineEntry(flowable.getPlainText(), key, level=int(style.name[-1]) - 1)

    def decorate(canv, doc):
        canv.saveState()
        canv.setFont(regular, 7)
        canv.setFillGray(0.35)
        w, h = A4
        canv.drawString(PAGE_MARGIN_MM * mm, h - 10 * mm, f"{content.name} · {content.scope_text}")
        canv.drawRightString(w - PAGE_MARGIN_MM * mm, 8 * mm, f"page {doc.page}")
        canv.drawString(PAGE_MARGIN_MM * mm, 8 * mm,
                        f"BridgeSurvey {content.versions.get('bridgesurvey', '')} · {content.generated}")
        canv.restoreState()

    doc = Doc(str(path), pagesize=A4, leftMargin=PAGE_MARGIN_MM * mm, rightMargin=PAGE_MARGIN_MM * mm,
              topMargin=16 * mm, bottomMargin=14 * mm, title=f"{content.name}: displacement survey report",
              author=content.author, subject=content.scope_text, creator="BridgeSurvey")
    frame = Frame(doc.leftMargin, doc.bottomMargin, doc.width, doc.height, id="body")
    doc.addPageTemplates([PageTemplate("title", [frame]), PageTemplate("body", [frame], onPage=decorate)])
    return doc


# ----------------------------------------------------------------------------- sections
def title_page(content: ReportContent, ss: Any) -> list:
    """Flowables of the title page."""
    p0, p1 = content.period
    rows = [["Structure", content.name], ["Report covers", content.scope_text],
            ["Period", f"{p0[:16].replace('T', ' ')}  to  {p1[:16].replace('T', ' ')}"],
            ["Span", f"{content.span_m:g} m" if content.span_m else "not given"],
            ["Scanner", content.scanner], ["Baseline epoch", content.baseline or "none yet"],
            ["Campaign folder", content.folder], ["Prepared by", content.author], ["Generated", content.generated],
            ["Software", f"BridgeSurvey {content.versions.get('bridgesurvey', '?')}, "
                         f"pipeline {content.versions['pipeline']}"]]
    return [Paragraph("Displacement survey report", ss["Sub"]), Spacer(1, 6), Paragraph(_esc(content.name), ss["Big"]),
            Spacer(1, 18), _table([["", ""]] + rows, (45, 130), ss, header_rows=1), Spacer(1, 18),
            Paragraph("Vertical displacements of the measurement targets under the deck, relative to the reference "
                      "targets on the piers, from terrestrial laser scans; positive is up, against the baseline "
                      "epoch. Uncertainties are one standard deviation propagated from every target centroid.",
                      ss["Normal"]),
            NextPageTemplate("body"), PageBreak()]


def summary_section(content: ReportContent, ss: Any) -> list:
    """Flowables of the summary: latest value of every target, problems, largest movement, limits."""
    out = [Paragraph("Summary", ss["Heading1"])]
    rows = content.displacements
    latest = {}
    for r in rows:  # the latest value of each target; an epoch without one does not hide the last good one
        if r["displacement_mm"] is not None or r["reflector"] not in latest:
            latest[r["reflector"]] = r
    if not rows:
        out.append(Paragraph("No displacements computed yet: the epochs in this report have not all been measured "
                             "(see the epoch sections; Epoch ▸ Process in the application, or "
                             "<font face='Courier'>bridgesurvey process DIR</font>).", ss["Normal"]))
    else:
        last_epoch = content.epochs[-1].label
        out.append(Paragraph(f"{len(content.epochs)} epoch(s) in this report; displacements against baseline "
                             f"epoch {_esc(content.baseline)}. Latest value of every measurement target "
                             f"(epoch {last_epoch} unless noted):", ss["Normal"]))
        table = [["Target", "Epoch", "Displacement [mm]", "σ [mm]", "Warning / alarm [mm]", "State", "Remarks"]]
        colours = []
        for k, rid in enumerate(sorted(latest), start=1):
            r = latest[rid]
            table.append([rid, r["epoch"], _num(r["displacement_mm"]), _num(r["sigma_mm"], "{:.3f}"),
                          f"{_num(r['warning_mm'], '{:.1f}')} / {_num(r['alarm_mm'], '{:.1f}')}", r["state"],
                          row_words(r)])
            colours.append((k, 5, STATE_COLOURS.get(r["state"], "#ffffff")))
        out += [Spacer(1, 4), _table(table, (18, 24, 26, 16, 30, 16, 48), ss, cell_colours=colours)]
        problem_epochs = []
        for sec in content.epochs:
            fl = sec.displacement_set.flags if sec.displacement_set else ()
            bad = [f for f in fl if severity(f) == "problem"]
            if bad:
                problem_epochs.append(f"{sec.label} ({summary(bad[:1])})")
        attention = [sec.label for sec in content.epochs if sec.state in ATTENTION_STATES]
        out.append(Spacer(1, 4))
        out.append(Paragraph(_esc(f"Visits that need attention: {', '.join(attention)} (a page each below)."
                                  if attention else "No visit in this report needs attention: every value is within "
                                                    "its σ or carries a remark that says why."), ss["Normal"]))
        if problem_epochs:
            out.append(Spacer(1, 4))
            out.append(Paragraph("<font color='#d62728'><b>Epochs without a trustworthy result:</b> " +
                                 _esc("; ".join(problem_epochs)) + "</font>", ss["Normal"]))
        valued = [r for r in rows if r["displacement_mm"] is not None]
        if valued:
            big = max(valued, key=lambda r: abs(r["displacement_mm"]))
            out.append(Spacer(1, 6))
            out.append(Paragraph(f"<b>Largest movement in this report:</b> {big['reflector']} at epoch {big['epoch']}: "
                                 f"{big['displacement_mm']:+.2f} ± {big['sigma_mm'] or 0:.2f} mm "
                                 f"(state {big['state']}).", ss["Normal"]))
            alarms = sorted({(r["reflector"], r["state"]) for r in valued if r["state"] in ("warning", "alarm")})
            if alarms:
                out.append(Paragraph("Targets that reached a limit during the period: " +
                                     ", ".join(f"{a} ({s})" for a, s in alarms) + ".", ss["Normal"]))
    if rows:
        fig = displacement_history_figure(content.histories, title="All measurement targets (bars ±2σ)",
                                          context=content.extras.get("context"), series=False, figsize=(7.0, 3.8))
        out += [Spacer(1, 6), figure_flowable(fig, 170)]
    out.append(Paragraph("Limits in force", ss["Heading2"]))
    if content.limits:
        lim_rows: list[list] = [["Applies to", "Rule", "Warning [mm]", "Alarm [mm]"]]
        for lr in content.limits:
            lim_rows.append(["every measurement target" if lr.reflector == "*" else lr.reflector, lr.limit.rule,
                             _num(lr.limit.warning_mm, "{:.1f}"), _num(lr.limit.alarm_mm, "{:.1f}")])
        out.append(_table(lim_rows, (50, 45, 30, 30), ss))
        out.append(Paragraph("States compare |displacement| with the thresholds: warning at or above the warning "
                             "value, alarm at or above the alarm value.", ss["Small"]))
    else:
        out.append(Paragraph("No limits set: Campaign ▸ Set limit… in the application, or "
                             "<font face='Courier'>bridgesurvey limit DIR --rule RULE</font>.", ss["Normal"]))
    return out


def layout_section(content: ReportContent, ss: Any) -> list:
    """Flowables of the layout figure and each target's state."""
    out = [PageBreak(), Paragraph("Reflector layout and target state", ss["Heading1"]),
           figure_flowable(layout_figure(content.reflectors, content.target_states, span_m=content.span_m), 170)]
    table = [["Target", "Group", "x / y / z [m]", "In use", f"Epoch {content.epochs[-1].label}"]]
    by_id = {r.id: r for r in content.reflectors}
    colours = []
    for k, s in enumerate(content.target_states, start=1):
        r = by_id[s.reflector]
        use = (f"from {s.installed[:10]}" if s.installed else "from start") + \
              (f", retired {s.retired[:10]}" if s.retired else "")
        found = "not measured" if s.found is None else ("found" if s.found else "NOT FOUND")
        table.append([s.reflector, s.group, " / ".join(f"{v:.2f}" for v in r.xyz_layout), use,
                      "; ".join((found,) + s.remarks)])
        if s.remarks or s.found is False:
            colours.append((k, 4, "#fff3e0"))
    out.append(_table(table, (16, 24, 38, 38, 62), ss, cell_colours=colours))
    return out


def history_section(content: ReportContent, ss: Any) -> list:
    """Flowables of the per-target history panels, six to a page."""
    out = [PageBreak(), Paragraph("Displacement history", ss["Heading1"])]
    targets = sorted(content.histories)
    if not targets:
        return out + [Paragraph("No displacements yet.", ss["Normal"])]
    out.append(Paragraph("Each panel is one measurement target; the legend above the panels says what each line "
                         "and colour is. Flagged values (black rings) carry a remark in the epoch sections; events are "
                         "numbered above the first panel.", ss["Small"]))
    ctx = content.extras.get("context")
    if ctx is not None and ctx.series_name and ctx.series_statistic == "daily means":
        out.append(Paragraph(_esc(f"{ctx.series_name}: means of whole days only (a day whose readings cover less "
                                  f"than {WHOLE_DAY_COVERAGE:.0%} of it is left out)."), ss["Small"]))
    for k in range(0, len(targets), 6):
        out.append(figure_flowable(history_grid_figure(content.histories, targets=targets[k:k + 6],
                                                       context=ctx), 175))
    return out


MAP_FIGSIZE = (7.0, 3.1)


def render_map_jpeg(preview: Any, plan: Any, label: str) -> bytes:
    """An epoch's map figure as JPEG bytes (JPEG goes into the PDF as it is, without re-encoding)."""
    fig = epoch_map_figure(preview, plan, title=f"Reflectance map, epoch {label} "
                                                "(orange rings: detections; red boxes: planned fine windows)")
    buf = io.BytesIO()
    fig.savefig(buf, format="jpg", dpi=130, pil_kwargs={"quality": 88})
    return buf.getvalue()


def _render_map_job(job) -> bytes | None:
    return render_map_jpeg(*job)


def render_maps(sections: Sequence[EpochSection], preview_of: Callable | None = None, *,
                progress: ProgressCallback | None = None, workers: int | None = None) -> list[bytes | None]:
    """Map images of many epochs, drawn in parallel worker processes when there are enough of them."""
    jobs = []
    for e in sections:
        report(progress, 0.0, f"map of {e.label}")
        p = e.preview if e.preview is not None else (preview_of(e.label) if preview_of else None)
        if p is not None:  # reduce before sending to a worker: the figure never needs more
            p = MapPreview(reduce_map(p.reflectance_map, max_cells=300_000), p.detections, p.identification,
                           p.full_step_deg)
        jobs.append(None if p is None else (p, e.plan.plan if e.plan else None, e.label))
    todo = [j for j in jobs if j is not None]
    workers = workers or min(os.cpu_count() or 1, 4)
    if len(todo) < 8 or workers < 2:
        images = []
        for k, j in enumerate(todo):
            report(progress, k / max(len(todo), 1), f"map {j[2]}")
            images.append(_render_map_job(j))
    else:
        # spawn, not fork: safe inside the desktop application's threads
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
        try:
            futures = [pool.submit(_render_map_job, j) for j in todo]
            pending = set(futures)
            while pending:  # a progress call every 0.25 s: it may cancel, and the maps left are not waited for
                pending = wait(pending, timeout=0.25).not_done
                report(progress, 1.0 - len(pending) / len(todo), "maps")
            images = [f.result() for f in futures]
        finally:
            pool.shutdown(wait=False, cancel_futures=True)
    it = iter(images)
    return [None if j is None else next(it) for j in jobs]


#: Text colour of an epoch state in the report (the campaign tree's orange and red).
STATE_TEXT_COLOURS = {"warning": "#b35900", "problem": "#d62728"}


def row_words(r: dict) -> str:
    """A displacement row's flags in words, most serious first (the report's body: no flag codes)."""
    flags = [f for f in r["flags"].split(";") if f]
    return summary(flags) if flags else "–"


def flags_text(flags, *, words: bool) -> str:
    """Flags as the body says them (words) or as the appendix lists them (codes, by severity)."""
    flags = [f for f in flags if f]
    if not flags:
        return ""
    return summary(flags) if words else describe(flags)


def state_line(e: EpochSection, *, words: bool = False) -> str:
    """``State: warning (second_bright_object: ...)`` as ``status --verbose`` gives it, then the epoch's notes.

    ``words``: as the one-line status says it, with the action. Returns markup.
    """
    colour = STATE_TEXT_COLOURS.get(e.state)
    state = f"<b>{_esc(e.state)}</b>" if colour is None else f"<font color='{colour}'><b>{_esc(e.state)}</b></font>"
    flags = flags_text(e.state_flags, words=words)
    text = f"State: {state}" + (f" ({_esc(flags)})" if flags else "") + "."
    todo = first_action(e.state_flags) if words else ""
    if todo:
        text += f" <b>To do:</b> {_esc(todo[:1].upper() + todo[1:])}."
    return text + (f" {_esc(e.notes)}" if e.notes else "")


def plan_table(stored: Any, centroids: dict, ss: Any, *, words: bool = False, setup: int | None = None) -> list:
    """The plan of an epoch (or of its set-up ``setup``) and what each window delivered; closure windows marked."""
    ident = stored.identification
    plan = stored.plan
    visit = stored.plan_json.get("visit") or {}
    who = f"Set-up {setup} (" + (f"{visit['position_in_order']}. of the visit's {len(visit['setups'])}, planned "
                                 "together" if visit else "planned alone") + "): " if setup is not None else "Plan: "
    closing = [r.reflector for r in plan.rois if r.closure]
    out = [Paragraph(_esc(f"{who}{len(plan.rois)} windows"
                          + (f" ({len(closing)} closure: {', '.join(closing)} again at the end)" if closing else "")
                          + f", {plan.total_seconds / 60:.1f} min planned; {ident.get('detections', '?')} detections, "
                          f"layout fit RMS {_num((ident.get('fit_rms_m') or float('nan')) * 100, '{:.1f}')} cm, "
                          f"predicted (not seen): {', '.join(ident.get('missing', [])) or 'none'}"
                          + (f"; joined by {', '.join(visit['ties'])}" if visit.get("ties") else "") + "."),
                     ss["Small"])]
    table = [["Target", "Steps φ×θ [°]", "Planned time [s]", "Planned pts on target", "Points in window",
              "Points on target", "σx / σy / σz [mm]", "Remarks" if words else "Flags"]]
    colours = []
    for k, r in enumerate(plan.rois, start=1):
        t = centroids.get(r.reflector)
        sig = "–" if t is None or not t.found else " / ".join(f"{v * 1000:.2f}" for v in t.sigma_m)
        flags = "not scanned yet" if t is None else (flags_text(t.flags, words=words) or "–")
        n_on = "–" if t is None else str(t.n_points)
        name = f"{k}. {r.reflector}" + (" (closure)" if r.closure else "")
        if r.closure:  # its points and sigma are the first window's; the closure itself gives the set-up's drift
            sig, flags, n_on = "–", "closure: the set-up's drift", "–"
        table.append([name, f"{r.window.phi_step_deg:.4f}×{r.window.theta_step_deg:.4f}",
                      f"{r.expected_seconds:.0f}", str(r.expected_target_points or "–"),
                      "–" if t is None or t.n_window < 0 or r.closure else str(t.n_window), n_on, sig, flags])
        if r.closure:
            colours.append((k, 0, "#e8f0fe"))
        elif t is not None and (t.flags or (r.expected_target_points and t.n_points < 0.5 * r.expected_target_points)):
            colours.append((k, 7, "#fff3e0"))
    return out + [Spacer(1, 3), _table(table, (18, 26, 16, 22, 20, 18, 30, 28), ss, cell_colours=colours)]


def epoch_section(e: EpochSection, content: ReportContent, ss: Any, *, new_page: bool = True,
                  map_jpeg: bytes | None = None, words: bool = False) -> list:
    """Flowables of one epoch; ``map_jpeg`` from :func:`render_maps` (None: the epoch has no map).

    ``words``: flags said in words (the main body's page of a visit that needs attention); otherwise their
    codes (the appendix, whose flag table explains them).
    """
    out = [PageBreak()] if new_page else []
    out += [Paragraph(f"{'Visit' if words else 'Epoch'} {_esc(e.label)} — {e.datetime[:16].replace('T', ' ')}",
                      ss["Heading2"]),
            Paragraph(state_line(e, words=words), ss["Small"])]
    if map_jpeg is not None:
        out.append(Image(io.BytesIO(map_jpeg), width=178 * mm, height=178 * mm * MAP_FIGSIZE[1] / MAP_FIGSIZE[0]))
    else:
        out.append(Paragraph("No coarse-scan map for this epoch.", ss["Small"]))
    plans = [(1, e.plan, e.centroids)] + [(k, sp, cents) for k, (sp, cents) in sorted(e.setup_plans.items())]
    for setup, stored, cents in plans:
        if stored:
            out += plan_table(stored, cents, ss, words=words, setup=setup if len(plans) > 1 else None)
    if e.reference_checks:
        table = [["Reference", "Median distance change [mm]", "Max change [mm]", "Verdict"]]
        for rc in e.reference_checks:
            verdict = "not found" if rc.missing else ("MOVED, left out" if rc.moved else
                                                     ("suspect" if rc.suspect else "stable"))
            table.append([rc.reflector, _num(None if rc.median_change_m is None else rc.median_change_m * 1000),
                          _num(None if rc.max_change_m is None else rc.max_change_m * 1000), verdict])
        out += [Spacer(1, 4), Paragraph("Reference group check", ss["Small"]), _table(table, (20, 45, 30, 35), ss)]
    if e.setups:  # the joint frame of a visit of several set-ups: its QA trail

        motions, residuals = join_tables(e.setups)
        out += [Spacer(1, 4), Paragraph(_esc("Set-ups: " + join_summary(e.setups)), ss["Small"]),
                _table(motions, (12, 70, 16, 20, 22, 22, 38), ss)]
        if len(residuals) > 1:
            out += [Spacer(1, 2), Paragraph("Joint frame residuals of the shared targets (largest first)", ss["Small"]),
                    _table(residuals, (20, 16, 24, 22, 20), ss)]
    rows = [r for r in content.displacements if r["epoch"] == e.label]
    if e.damaged:
        out.append(Paragraph(f"<font color='#d62728'><b>DAMAGED:</b> {_esc(e.damaged)}</font>", ss["Normal"]))
    if rows:
        table = [["Target", "Displacement [mm]", "σ [mm]", "State", "Remarks" if words else "Flags"]]
        for r in rows:
            table.append([r["reflector"], _num(r["displacement_mm"]), _num(r["sigma_mm"], "{:.3f}"), r["state"],
                          row_words(r) if words else (r["flags"].replace(";", ", ") or "–")])
        epoch_flags = e.displacement_set.flags if e.displacement_set else ()
        said = flags_text(epoch_flags, words=words)
        out += [Spacer(1, 4), Paragraph("Displacements" + (f" (the visit: {_esc(said)})" if said else ""),
                                        ss["Small"]), _table(table, (20, 30, 20, 20, 88), ss)]
        corrected = corrections_line(e.systematics, baseline=e.label == content.baseline)
        if corrected:
            out.append(Paragraph(_esc(f"Corrected for: {corrected}."), ss["Small"]))
        problems = [f for f in epoch_flags if severity(f) == "problem"]
        if problems:
            out.insert(1 if new_page else 0, Paragraph(
                f"<font color='#d62728'><b>PROBLEM:</b> {_esc(flags_text(problems, words=words))}</font>",
                ss["Normal"]))
    return out


def _flags_in(content: ReportContent) -> set[str]:
    """The flag codes that appear anywhere in the report's epochs."""
    used: set[str] = set()
    for e in content.epochs:
        used.update(e.state_flags)
        used.update(e.displacement_set.flags if e.displacement_set else ())
        for t in e.centroids.values():
            used.update(t.flags)
    for r in content.displacements:
        used.update(f for f in (r["flags"] + ";" + (r.get("epoch_flags") or "")).split(";") if f)
    return {code(f) for f in used}


def log_section(content: ReportContent, ss: Any, *, max_log_rows: int = 400) -> list:
    """Flowables of the processing log: versions, parameters, file checksums, flags and the action log."""
    out = [PageBreak(), Paragraph("Appendix C: processing log", ss["Heading1"]),
           Paragraph("Everything needed to trace the numbers: software versions, processing parameters, the "
                     "checksum of every scan file used, and the campaign's action log.", ss["Small"]),
           Paragraph("Software", ss["Heading2"]),
           _table([["Component", "Version"]] + [[k, v] for k, v in content.versions.items()], (50, 50), ss),
           Paragraph("Processing parameters", ss["Heading2"]),
           _table([["Parameter", "Value"]] + [[k, "auto" if v is None else str(v)]
                                              for k, v in content.parameters.items()], (60, 50), ss),
           Paragraph("Scan files (SHA-256, stored read-only in the campaign)", ss["Heading2"])]
    files: list[list] = [["Epoch", "Role", "Original file", "Size [MB]", "SHA-256"]]
    for e in content.epochs:
        for f in e.files:
            files.append([e.label, f.role, os.path.basename(f.original_path), f"{f.size / 1e6:.1f}",
                          Paragraph(f.sha256, ss["Mono"])])
    out.append(_table(files, (20, 15, 40, 14, 89), ss))
    out.append(Paragraph("Flags raised in this report", ss["Heading2"]))
    used = _flags_in(content)
    flag_rows = [[f.code, f.severity, f.meaning] for f in REGISTRY.values() if f.code in used]
    if flag_rows:
        out.append(_table([["Flag", "Severity", "Meaning"]] + flag_rows, (50, 18, 110), ss))
    else:
        out.append(Paragraph("No flag was raised in this report's epochs.", ss["Small"]))
    out.append(Paragraph("Action log", ss["Heading2"]))
    log = list(content.log)
    if len(log) > max_log_rows:
        out.append(Paragraph(f"The last {max_log_rows} of {len(log)} entries; the workbook export (Reports ▸ "
                             "Export workbook… or <font face='Courier'>bridgesurvey export DIR</font>) has them all.",
                             ss["Small"]))
        log = log[-max_log_rows:]
    rows: list[list] = [["Time (UTC)", "Epoch", "Action", "Files", "Result"]]
    for entry in log:
        a = action_row(entry)
        rows.append([a.time, a.epoch or "–", a.action, a.files or "–", a.result or "–"])
    out.append(_table(rows, (30, 18, 35, 30, 65), ss))
    return out


def comparison_section(content: ReportContent, ss: Any) -> list:
    """Flowables of the whole-scan comparisons and span profiles."""
    out = [PageBreak(), Paragraph("Epoch comparison and span profile", ss["Heading1"]),
           Paragraph("The conventional whole-scan approach, for context: both epochs registered into the campaign "
                     "frame (reference targets as tie points, then ICP on the piers and the ground around them), "
                     "their change computed point by point, and the height of the deck underside (only its points, a "
                     "plane fitted per 2.5 m bin) compared along the girder lines. Each RMS below says what it is "
                     "computed on. Compare the spread with the targets' uncertainty.", ss["Small"])]
    for s in content.extras["comparisons"]:
        out.append(Paragraph(f"{_esc(s['from'])} → {_esc(s['to'])} ({s['method'].upper()})", ss["Heading2"]))
        lines = [line + "".join(f" — warning: {w}" for w in s["registration"][lab]["targets"]["warnings"])
                 for lab, line in registration_lines(s)]
        out += [Paragraph(_esc(t), ss["Small"]) for t in lines]
        table = [["Computed on", "Points", "Median [mm]", "RMS [mm]", "Std [mm]", "95 % |d| [mm]", "Median LoD [mm]"]]
        for part, name in (("stable_parts", "stable parts: piers and ground"), ("deck", "deck underside near targets"),
                           ("all", "all points compared")):
            st = s["change"][part]
            table.append([name, str(st["n"]), _num(st.get("median_mm")), _num(st.get("rms_mm")), _num(st.get("std_mm")),
                          _num(st.get("p95_abs_mm")), _num(st.get("median_lod_mm"))])
        out += [Spacer(1, 3), _table(table, (46, 18, 22, 20, 20, 24, 26), ss), Spacer(1, 4)]
        if s["span_profile"]["bins"]:
            out.append(figure_flowable(span_profile_figure(s), 172))
            spread = [np.hypot(b["std_from_mm"], b["std_to_mm"]) / np.sqrt(2) for b in s["span_profile"]["bins"]]
            tsig = [t["sigma_mm"] for t in s["targets"]]
            out.append(Paragraph(f"Height spread of the scan points per {s['span_profile']['bin_m']:g} m bin: median "
                                 f"{np.median(spread):.1f} mm; target displacement σ: median "
                                 f"{np.median(tsig) if tsig else float('nan'):.2f} mm.", ss["Small"]))
    return out


def crossval_section(content: ReportContent, ss: Any) -> list:
    """Flowables of the dual-camera cross-checks."""
    out = [PageBreak(), Paragraph("Cross-check with the dual-camera system", ss["Heading1"]),
           Paragraph("The camera series of the midspan target (its own zero, set by the alignment below) against "
                     "the LiDAR displacements: each epoch is paired with the median of the camera samples around "
                     "its time.", ss["Small"])]
    for stored, camera in content.extras["crossvals"]:
        cv = CrossValidation.from_json(stored)
        al = cv.alignment
        how = (f"aligned at epoch {al['epoch']}" if al["method"] == "at-date" else "aligned by least squares")
        out.append(Paragraph(f"{_esc(cv.series)} against LiDAR target {_esc(cv.reflector)}", ss["Heading2"]))
        out.append(Paragraph(_esc(f"{len(camera):,} camera samples from {camera.summary()['start'][:10]} to "
                                  f"{camera.summary()['end'][:10]}; pairing window ±{cv.window_s / 60:g} min; {how}, "
                                  f"offset {cv.offset_mm:+.2f} mm."), ss["Small"]))
        table = [["Pairs", "Bias [mm]", "RMSE [mm]", "Std [mm]", "Max |d| [mm]", "Correlation", "Within 2σ"],
                 [f"{cv.n_pairs} of {len(cv.pairs)}", _num(cv.bias_mm, "{:+.2f}"), _num(cv.rmse_mm), _num(cv.std_mm),
                  _num(cv.max_abs_mm), _num(cv.correlation, "{:.3f}"), _num(100 * cv.within_2sigma, "{:.0f} %")]]
        out += [Spacer(1, 3), _table(table, (24, 22, 22, 20, 24, 24, 22), ss), Spacer(1, 4)]
        if not cv.has_statistics:
            out.append(Paragraph(_esc(f"{cv.note[:1].upper()}{cv.note[1:]}. Import a longer camera series or widen "
                                      "the pairing window ('bridgesurvey crossval DIR --window-min MIN')."),
                                 ss["Normal"]))
        out += [
                figure_flowable(overlay_figure(cv, camera), 172), figure_flowable(difference_figure(cv), 172),
                figure_flowable(scatter_figure(cv), 90)]
        missing = [p.epoch for p in cv.pairs if FLAG_NO_CAMERA_DATA in p.flags]
        if missing:
            out.append(Paragraph(_esc(f"No camera data around: {', '.join(missing)}."), ss["Small"]))
    return out


#: Optional sections: name -> builder taking (content, ss) and returning flowables; called only when
#: ``content.extras`` holds that name.
EXTRA_SECTIONS: dict[str, Callable] = {"comparisons": comparison_section, "crossvals": crossval_section,
                                       "analysis": analysis_section, "field": field_section}


def attention_section(content: ReportContent, ss: Any, maps: Sequence[bytes | None]) -> list:
    """The visits that need attention (a warning or a problem), a page each, in words.

    None of them: nothing (the summary says so in one line).
    """
    chosen = [(e, m) for e, m in zip(content.epochs, maps, strict=True) if e.state in ATTENTION_STATES]
    if not chosen:  # the summary says so in one line
        return []
    out = [PageBreak(), Paragraph("Visits that need attention", ss["Heading1"])]
    out.append(Paragraph(_esc(f"{len(chosen)} of {len(content.epochs)} visits: each with what was seen, what to do, "
                              "its map and its values. The other visits' pages are in the appendix."), ss["Small"]))
    for k, (e, jpeg) in enumerate(chosen):
        out += epoch_section(e, content, ss, new_page=k > 0, map_jpeg=jpeg, words=True)
    return out


def appendix_note(content: ReportContent, ss: Any) -> list:
    """The main body's last lines when the appendix is left out: where the detail is."""
    return [Spacer(1, 10), Paragraph("Appendix", ss["Heading1"]),
            Paragraph("Not included in this report: every visit's page (map, plan, centroids and their flags), the "
                      "field model's per-visit tables, the processing parameters, the scan files' checksums, the flag "
                      "codes and the action log. Write the report with the appendix (<font face='Courier'>"
                      "bridgesurvey report DIR --out FILE --detail</font>), or export the tables (<font face='Courier'>bridgesurvey export DIR</font>).",
                      ss["Small"])]


def build_pdf(content: ReportContent, path: str | os.PathLike, *, preview_of: Callable | None = None,
              progress: ProgressCallback | None = None, detail: bool = False) -> Path:
    """Write the report to ``path`` (through a temporary file, so a failure leaves no half PDF).

    The main body: title, summary, the visits that need attention (a page each), layout, histories and the
    optional sections (analysis, field budget, comparisons, camera cross-checks), in words. ``detail`` adds
    the appendix: every visit's page, the field model's tables and the processing log with flag codes.
    """
    path = Path(path)
    ss = _styles()
    story = title_page(content, ss)
    report(progress, 0.02, "summary")
    story += summary_section(content, ss)
    shown = [e for e in content.epochs if detail or e.state in ATTENTION_STATES]
    maps = render_maps(shown, preview_of, progress=scaled(progress, 0.03, 0.5))
    by_label = {e.label: m for e, m in zip(shown, maps, strict=True)}
    report(progress, 0.5, "visits that need attention")
    story += attention_section(content, ss, [by_label.get(e.label) for e in content.epochs])
    report(progress, 0.52, "layout")  # between the sections: each call lets a cancel stop the report
    story += layout_section(content, ss)
    report(progress, 0.55, "history")
    story += history_section(content, ss)
    for name, builder in EXTRA_SECTIONS.items():
        if name in content.extras:
            report(progress, 0.6, name)
            story += builder(content, ss)
    if not detail:
        story += appendix_note(content, ss)
    else:
        story += [PageBreak(), Paragraph("Appendix A: every visit", ss["Heading1"]),
                  Paragraph("Per visit: the coarse scan's reflectance map with detections and the planned fine-scan "
                            "windows, the plan against what the fine scans held, the centroids with their "
                            "uncertainty and flags, the reference check and the displacements. Flag codes are "
                            "explained in appendix C.", ss["Small"])]
        for k, e in enumerate(content.epochs):
            report(progress, 0.65 + 0.2 * k / len(content.epochs), f"epoch {e.label}")
            story += epoch_section(e, content, ss, new_page=k > 0, map_jpeg=by_label.get(e.label))
        if "field" in content.extras:
            story += field_appendix(content, ss)
        story += log_section(content, ss)
    report(progress, 0.9, "writing PDF")

    with atomic_output(path) as tmp:
        _make_doc(tmp, content).build(story)
    report(progress, 1.0, "report written")
    return path

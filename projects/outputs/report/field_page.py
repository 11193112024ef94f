"""The report's field error budget: what the campaign's instrument did, and what each term of σ holds.

One page: the range walk and the axis errors, each visit's scale and drift (figure and table), then per
epoch the median of each budget term over its targets, so a reader sees what the displacements were
corrected for and how much of their σ each correction costs.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from reportlab.platypus import PageBreak, Paragraph, Spacer

from lidar.systematic.adjustment import ALTERNATIVE_BIC
from lidar.systematic.range_walk import PLAUSIBLE_BIC, describe_basis, plausible
from projects.outputs.field_figures import field_model_figure
from projects.outputs.report.content import ReportContent
from projects.outputs.report.flowables import esc, figure_flowable, num, table
from projects.results.corrections import epoch_corrections
from projects.results.table import BUDGET_COLUMNS

FIGURE_SIZE_IN = (7.6, 2.7)
INTRO = ("Each visit's centroids are corrected before their displacements are computed: for the atmosphere's "
         "range scale (ppm against the baseline's visit), for the retro-reflectors' range walk (a bias along the "
         "beam that depends on range and incidence, one law for the campaign), for the instrument's axis errors "
         "(collimation, trunnion and vertical index, one set for the campaign, where the data support them) and "
         "for the set-up's drift during the visit (tilt and twist rates, measured on the reference targets and on "
         "the closure window that scans the first reference again at the end). They are fitted jointly over every "
         "visit; what the data cannot tell apart widens σ instead of moving the value. The budget below splits σ "
         "into its terms: noise (the centroids), frame (the reference targets' fit), scale, bias (range walk and "
         "axis errors) and drift.")


def _range_walk_text(content: ReportContent, *, detail: bool = True) -> str:
    """The instrument as the field model found it; ``detail``: with the competing laws and the adjustment's size."""
    model = content.extras["field"]["model"]
    rw = model.range_walk
    text = f"Range walk: {describe_basis(rw.basis)}"
    if rw.basis:
        text += " (r0 = 15 m)" if any("r2" in b or "strength" in b or b.startswith("step_q") for b in rw.basis) else ""
        text += "; determined by the campaign's data" if rw.determined else "; not determined: its prior is in σ"
    if not detail:
        close = sum(plausible([a[2] for a in rw.alternatives])) if len(rw.alternatives) > 1 else 1
        if close > 1:
            text += (f"; {close - 1} other law{'s' if close > 2 else ''} fit the data about as well, and the largest "
                     "difference they would make is included in σ")
        return text + f". The instrument's axis errors the data support: {model.axes.describe()}."
    if len(rw.alternatives) > 1:
        ranked = sorted(rw.alternatives, key=lambda a: -a[2])
        close = [a for a, ok in zip(ranked, plausible([a[2] for a in ranked]), strict=False) if ok]
        text += (f"; {len(ranked)} laws came within {ALTERNATIVE_BIC:g} BIC units of it, {len(close)} within "
                 f"{PLAUSIBLE_BIC:g} (as credible): the largest departure among those is in σ "
                 f"({', '.join(describe_basis(b) for b, _, _ in close[:3])}{', …' if len(close) > 3 else ''})")
    text += f". The instrument's axis errors the data support: {model.axes.describe()}"
    text += f". Adjustment: {model.n_observations} observations, σ0 {model.sigma0:.2f}."
    notes = list(rw.notes) + list(model.notes)
    return text + (" " + " ".join(notes) if notes else "")


def visit_rows(content: ReportContent) -> list[list]:
    """One row per epoch: scale, tilt and twist rates with σ, time source, misfit, targets left out."""
    extra = content.extras["field"]
    model = extra["model"]
    rows: list[list] = [["Epoch", "Scale [ppm]", "Tilt [″/h]", "Twist [″/h]", "Times", "Misfit", "Left out"]]
    for e in content.epochs:
        corr = epoch_corrections(extra["systematics"].get(e.label) or {})
        v = model.visits.get(e.label)
        if corr is None:
            rows.append([e.label, "–", "–", "–", "–", "–", "not processed with the field model"])
            continue
        base = e.label == model.baseline
        scale = ("0 (baseline)" if base else num(corr.scale_ppm, "{:+.1f}") + " ± " + num(corr.scale_sigma_ppm, "{:.1f}")
                 + ("" if corr.scale_determined else " (prior)"))
        tilt = num(corr.tilt_arcsec_h, "{:.0f}") + " ± " + num(corr.tilt_sigma_arcsec_h, "{:.0f}") if corr.timed else "–"
        twist = num(corr.twist_arcsec_h, "{:.0f}") + " ± " + num(corr.twist_sigma_arcsec_h, "{:.0f}") if corr.timed else "–"
        rows.append([e.label, scale, tilt, twist, corr.time_source, num(None if v is None else v.misfit),
                     ", ".join(corr.left_out) or "–"])
    return rows


def budget_rows(content: ReportContent) -> list[list]:
    """Per epoch, the median over its targets of each σ term and of σ itself (mm)."""
    names = [c[6:-3] for c in BUDGET_COLUMNS]
    rows: list[list] = [["Epoch", "Targets"] + [f"σ {n} [mm]" for n in names] + ["σ [mm]"]]
    for e in content.epochs:
        mine = [r for r in content.displacements if r["epoch"] == e.label and r["displacement_mm"] is not None]
        if not mine:
            continue
        med = [np.median([r[c] for r in mine if r.get(c) is not None] or [np.nan]) for c in BUDGET_COLUMNS]
        rows.append([e.label, str(len(mine))] + [num(float(v), "{:.3f}") for v in med]
                    + [num(float(np.median([r["sigma_mm"] for r in mine])), "{:.3f}")])
    return rows


def _overview(content: ReportContent) -> str:
    """The visits' corrections and the budget in a few sentences (the main body; the tables are in the appendix)."""
    extra = content.extras["field"]
    corr = [c for c in (epoch_corrections(extra["systematics"].get(e.label) or {}) for e in content.epochs)
            if c is not None]
    parts = []
    scales = [c.scale_ppm for c in corr]
    if scales:
        parts.append(f"the atmosphere's range scale ranged from {min(scales):+.0f} to {max(scales):+.0f} ppm "
                     f"(median σ {np.median([c.scale_sigma_ppm for c in corr]):.1f} ppm)")
    drift = [np.hypot(c.tilt_arcsec_h, c.twist_arcsec_h) for c in corr if c.timed]
    if drift:
        parts.append(f"the set-ups drifted by up to {max(drift):.0f}″/h (median {np.median(drift):.0f}″/h)")
    left = sorted({t for c in corr for t in c.left_out})
    if left:
        parts.append(f"targets left out of a visit's fit for not fitting it: {', '.join(left)}")
    valued = [r for r in content.displacements if r["displacement_mm"] is not None]
    if valued:
        names = [c[6:-3] for c in BUDGET_COLUMNS]
        med = [np.median([r[c] for r in valued if r.get(c) is not None] or [np.nan]) for c in BUDGET_COLUMNS]
        terms = ", ".join(f"{n} {v:.3f}" for n, v in zip(names, med, strict=True) if np.isfinite(v))
        parts.append(f"over the report's {len(valued)} values the median σ is "
                     f"{np.median([r['sigma_mm'] for r in valued]):.3f} mm, of which (each term's median, mm) {terms}")
    return ("Over these visits " + "; ".join(parts) + ".") if parts else ""


def field_section(content: ReportContent, ss: Any) -> list:
    """Flowables of the field error budget (``content.extras['field']``): the main body's page, in words."""
    extra = content.extras["field"]
    return [PageBreak(), Paragraph("Field error budget", ss["Heading1"]), Paragraph(esc(INTRO), ss["Small"]),
            Spacer(1, 3),
            figure_flowable(field_model_figure(extra["model"], extra["times"], measured=extra["measured"],
                                               figsize=FIGURE_SIZE_IN), 176),
            Paragraph(esc(_range_walk_text(content, detail=False)), ss["Small"]), Spacer(1, 3),
            Paragraph(esc(_overview(content)), ss["Small"])]


def field_appendix(content: ReportContent, ss: Any) -> list:
    """The field model's tables (appendix B): the laws it weighed, each visit's corrections, the budget by visit."""
    out = [PageBreak(), Paragraph("Appendix B: the field model by visit", ss["Heading1"]),
           Paragraph(esc(_range_walk_text(content)), ss["Small"]),
           Paragraph("Each visit's corrections", ss["Heading2"]),
           table(visit_rows(content), (24, 30, 22, 22, 16, 14, 48), ss)]
    budget = budget_rows(content)
    if len(budget) > 1:
        out += [Paragraph("The budget: median σ of each term over the epoch's targets", ss["Heading2"]),
                table(budget, (24, 14, 20, 20, 20, 20, 20, 18), ss),
                Paragraph("The terms add in quadrature except where they share a source (the frame and the scale "
                          "both come from the reference targets); σ is the displacement's own, from the full "
                          "covariance.", ss["Small"])]
    return out

"""HTML of the details panel: the campaign, a reflector, an epoch, a camera series (no Qt here)."""
from __future__ import annotations

import html

import numpy as np

from app.gui.state.words import windows_text
from common.flags import describe
from lidar.setups import join_summary, join_tables
from projects.processing.stages import baseline_epoch
from projects.results.corrections import corrections_line, instrument_line
from projects.results.state import epoch_state
from projects.results.status import storage_line
from projects.store.history import histories


def _rows(pairs) -> str:
    return "<table cellspacing=2>" + "".join(
        f"<tr><td><b>{html.escape(str(k))}</b></td><td>{html.escape(str(v))}</td></tr>" for k, v in pairs) + "</table>"


def campaign_html(c, status: dict) -> str:
    n_proc = sum(e["state"] in ("processed", "warning", "problem") for e in status["epochs"])
    rows = [("Folder", str(c.folder)), ("Span", f"{c.span_m:g} m" if c.span_m else "-"), ("Scanner", c.profile.name),
            ("Time zone", f"{c.timezone} (imported times without an offset)"),
            ("Epochs", f"{len(status['epochs'])} ({n_proc} processed)"), ("Baseline", status["baseline"] or "-"),
            ("Reflectors", len(c.reflectors()))]
    if status.get("instrument"):  # what the field model found of the instrument, as `status` says it
        rows.append(("Instrument", instrument_line(status["instrument"])))
    if status.get("storage"):  # the folder's size and where its scans are ('bridgesurvey archive')
        rows.append(("Storage", storage_line(status["storage"]).removeprefix("storage: ")))
    return f"<h3>{html.escape(c.name)}</h3>" + _rows(rows)


def reflector_html(c, rid: str) -> str:
    r = c.reflector(rid)
    rows = [("Group", r.group), ("Layout position", ", ".join(f"{v:.3f}" for v in r.xyz_layout) + " m"),
            ("Diameter", f"{r.diameter_m * 1000:.0f} mm")]
    for name, value in (("Installed", r.installed), ("Retired", r.retired), ("Replaces", r.replaces)):
        if value:
            rows.append((name, value))
    lim = None if r.is_reference else c.limit_for(rid)
    if lim is not None:
        rows.append(("Limits", f"warning {lim.warning_mm:.2f} mm, alarm {lim.alarm_mm:.2f} mm ({lim.rule})"))
    h = histories(c, targets=[rid]).get(rid)
    h = h.measured() if h is not None else None
    if h is not None and len(h):
        rows.append(("Latest", f"{h.displacement_mm[-1]:+.3f} ± {h.sigma_mm[-1]:.3f} mm ({h.epochs[-1]})"))
        vals = h.displacement_mm
        rows.append(("Range", f"{vals.min():+.2f} .. {vals.max():+.2f} mm over {len(h)} epochs"))
        if h.flags[-1]:
            rows.append(("Flags", ", ".join(h.flags[-1])))
    return f"<h3>Reflector {html.escape(rid)}</h3>" + _rows(rows)


def epoch_html(c, label: str) -> str:
    e = c.epoch(label)
    state, flags = epoch_state(c, label)
    rows = [("Date", e.datetime), ("State", state), ("Notes", e.notes or "-")]
    if flags:
        rows.append(("Flags", describe(flags)))
    for f in c.files(label, setup=None):
        rows.append((f"{f.role} scan" + (f" (set-up {f.setup})" if f.setup != 1 else ""),
                     f"{f.original_path.rsplit('/', 1)[-1]} ({f.size / 1e6:.1f} MB, sha256 {f.sha256[:12]}…)"))
    stored = c.stored_plan(label)
    if stored is not None:
        rows.append(("Plan", f"{windows_text(stored.plan.rois)}, {stored.plan.total_seconds / 60:.1f} min"
                             + (" (edited by hand)" if stored.edited else "")))
    corrected = corrections_line(c.systematics(label), baseline=label == baseline_epoch(c))
    if corrected:
        rows.append(("Corrected for", corrected))
    out = f"<h3>Epoch {html.escape(label)}</h3>" + _rows(rows)
    cents = c.centroids(label)
    if cents:
        out += "<h4>Centroids</h4><table cellspacing=3><tr><th>target</th><th>n</th><th>σ [mm]</th><th>flags</th></tr>"
        for rid, t in cents.items():
            sig = float(np.sqrt(np.trace(t.cov))) * 1e3 if t.found else float("nan")
            out += (f"<tr><td>{rid}</td><td>{t.n_points}</td><td>{sig:.3f}</td>"
                    f"<td>{html.escape(', '.join(t.flags)) or '-'}</td></tr>")
        out += "</table>"
    joined = c.systematics(label).get("setups")
    if joined:  # a visit of several set-ups: how they were joined (the joint frame's QA trail)

        out += f"<h4>Set-ups</h4><p>{html.escape(join_summary(joined))}</p>"
        for table in join_tables(joined):
            out += "<table cellspacing=3>" + "".join(
                "<tr>" + "".join(f"<t{'h' if n == 0 else 'd'}>{html.escape(v)}</t{'h' if n == 0 else 'd'}>"
                                 for v in row) + "</tr>" for n, row in enumerate(table)) + "</table>"
    return out


def series_html(row) -> str:
    """A camera series (a :class:`projects.records.SeriesRecord`)."""
    s = row.summary
    return (f"<h3>Camera series {html.escape(row.name)}</h3>" + _rows([
        ("Target", row.reflector or "-"), ("Rows", f"{s['rows']:,}"), ("Period", f"{s['start']} .. {s['end']}"),
        ("Sampling", f"{s['sampling_s']:.0f} s"), ("Gaps", s["gaps"]), ("Missing values", s["missing_values"]),
        ("Bad rows", s["bad_rows"]), ("File", row.original_path), ("sha256", row.sha256[:16] + "…")]))

"""The figure of a whole-scan comparison: the span profile against the targets."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure


def span_profile_figure(summary: dict):
    """Span profile of a comparison: per-bin underside height change (±2σ) and spread, with the targets' changes."""
    prof = summary["span_profile"]
    girders = sorted({b["girder"] for b in prof["bins"]} | {t["girder"] for t in summary.get("targets", [])})
    fig = Figure(figsize=(9, 2.6 + 1.6 * max(len(girders), 1)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(max(len(girders), 1), 1, sharex=True))
    for ax, g in zip(axes, girders or [1], strict=False):
        bins = [b for b in prof["bins"] if b["girder"] == g]
        if bins:
            s = np.array([b["station_m"] for b in bins])
            ch = np.array([b["change_mm"] for b in bins])
            sig = np.array([b["sigma_change_mm"] for b in bins])
            spread = np.array([np.hypot(b["std_from_mm"], b["std_to_mm"]) for b in bins])
            ax.bar(s, ch, width=prof["bin_m"] * 0.9, color="0.8", edgecolor="0.5",
                   label=f"deck underside, {prof['bin_m']:g} m bins (±2σ with the registration)")
            ax.errorbar(s, ch, yerr=2 * sig, fmt="none", ecolor="0.3", capsize=2)
            ax.fill_between(s, -spread, spread, color="tab:orange", alpha=0.15, step="mid",
                            label="point spread per bin (±1 std)")
        tg = [t for t in summary.get("targets", []) if t["girder"] == g]
        if tg:
            ax.errorbar([t["station_m"] for t in tg], [t["displacement_mm"] for t in tg],
                        yerr=[2 * t["sigma_mm"] for t in tg], fmt="o", color="tab:blue", capsize=3,
                        label="targets (±2σ)")
            for t in tg:
                ax.annotate(t["reflector"], (t["station_m"], t["displacement_mm"]), xytext=(4, 4),
                            textcoords="offset points", fontsize=7, color="tab:blue")
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_ylabel(f"girder line {g}\nchange [mm]")
        ax.grid(alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    for ax in axes[1:]:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=False):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if handles:
        axes[0].legend(handles, labels, fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3,
                       frameon=False)
    fig.suptitle(f"Span profile {summary['from']} → {summary['to']}: underside height change per bin "
                 "(plane fitted at the bin centre) and the targets", fontsize=10)
    axes[-1].set_xlabel("station along the layout's x from the first pier [m]")
    return fig

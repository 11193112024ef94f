"""Campaign figures (matplotlib, no GUI toolkit)."""
from __future__ import annotations

from typing import Mapping


from projects.store.history import DisplacementHistory


def displacement_history_figure(histories: Mapping[str, DisplacementHistory], *,
                                title: str = "Vertical displacement history", context=None):
    """Displacement of every measurement target over time with 2-sigma error bars and limit lines.

    Also the events and an environment series of ``context``, a :class:`projects.context.PlotContext`).

    ``histories`` as :func:`projects.history.histories` gives them (reflector -> history).
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 5), dpi=110, layout="constrained")
    ax = fig.add_subplot(1, 1, 1)
    drawn = False
    for rid in sorted(histories):
        h = histories[rid].measured()
        if len(h):
            ax.errorbar(h.times, h.displacement_mm, yerr=2 * h.sigma_mm, marker="o", ms=3, lw=1, capsize=2,
                        label=rid)
            drawn = True
    lims = {(h.limit.warning_mm, h.limit.alarm_mm) for h in histories.values()
            if h.limit is not None and h.limit.alarm_mm}
    for w, a in sorted(lims):
        for v, style, name in ((w, ":", "warning"), (a, "--", "alarm")):
            if v:
                ax.axhline(-v, color="tab:orange" if name == "warning" else "tab:red", ls=style, lw=1,
                           label=f"{name} -{v:.1f} mm")
    ax.axhline(0, color="0.6", lw=0.8)
    ax.set_ylabel("displacement [mm] (positive up, ±2σ)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if drawn:
        ax.legend(ncol=4, fontsize=8, loc="lower left")
        from projects.series.context import draw_context

        draw_context(ax, context)
    fig.autofmt_xdate()
    return fig

"""A report of a 100-epoch campaign takes under a minute (issue 7).

Builds a campaign of N processed epochs (default 100, as in bench_campaign), then times
``bridgesurvey report --detail`` (every epoch's page) and the main body alone on it, each in a fresh process. Baseline, measured in the same run: drawing
every epoch's stored map with plain matplotlib (imshow + savefig PNG), the irreducible part of
the report's work. Usage: ``./run bench bench_report [N_EPOCHS]`` (``--small``: 2 epochs, coarse scans at 0.12 degrees).
"""
from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[0]))

from _harness import OUT, figures, measure, row, small_mode  # noqa: E402
from bench_campaign import build_campaign  # noqa: E402


def main(n: int = 100, *, coarse_step_deg: float = 0.06) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="bench_report_", dir=OUT))
    try:
        camp, _ = build_campaign(work, n, report_every=25, coarse_step_deg=coarse_step_deg)
        pdf = work / "report.pdf"
        base = measure(f"""
            import io
            import matplotlib
            matplotlib.use("Agg")
            from matplotlib.figure import Figure
            from projects.store.campaign import Campaign
            c = Campaign.open({str(camp)!r}, writable=False)
            labels = [e.label for e in c.epochs()]
        """, """
            for lab in labels:
                m = c.map_preview(lab).reflectance_map
                fig = Figure(figsize=(7, 3.1))
                fig.add_subplot().imshow(m.max_intensity, cmap="gray", aspect="auto")
                fig.savefig(io.BytesIO(), format="png", dpi=130)
        """, repeat=1)
        rep = measure("from app.cli.main import main", f"""
            assert main(["report", {str(camp)!r}, "--out", {str(pdf)!r}, "--detail"]) == 0
        """, repeat=1)
        body = measure("from app.cli.main import main", f"""
            assert main(["report", {str(camp)!r}, "--out", {str(work / "body.pdf")!r}]) == 0
        """, repeat=1)
        print(row(f"plain matplotlib: {n} stored maps to PNG", base))
        print(row(f"bridgesurvey report --detail, {n} epochs", rep, base))
        print(row(f"bridgesurvey report (main body), {n} epochs", body, base))
        print(f"RESULT report of {n} epochs: {rep['seconds']:.1f} s (target < 60 s), x{rep['seconds'] / base['seconds']:.2f}"
              f" of the plain map drawing; {pdf.stat().st_size / 1e6:.1f} MB, peak {rep['peak_mb']:.0f} MiB")
        figures(epochs=n, seconds=rep["seconds"], ratio_to_plain=rep["seconds"] / base["seconds"],
                pdf_mb=pdf.stat().st_size / 1e6, body_seconds=body["seconds"])
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 2 if _small else 100, coarse_step_deg=0.12 if _small else 0.06)

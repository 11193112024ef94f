"""Camera series import: 1.5 years of 1-minute samples (~800,000 rows) against a plain pandas read.

The baseline, measured in the same run, is ``pandas.read_csv`` with ISO time parsing of the same
file -- what a script would do without any checks. Ours also finds bad rows with their line
numbers, gaps, NaNs, units and zones. Usage: ``./run bench bench_camera_import [ROWS]`` (``--small``: 20,000
rows, one process each).
"""
from __future__ import annotations

import numpy as np
from _harness import OUT, figures, measure, row, small_mode


def make_file(path, n):
    from vision.simulate.series import simulate_series, write_series_csv

    if path.exists():
        return
    start = np.datetime64("2025-01-01T00:00", "ns").astype(np.int64)
    end = start + (n - 1) * 60 * 10 ** 9
    t, v = simulate_series(start, end, lambda t: -5.0 * np.sin((t - start) / 3e16), noise_mm=0.2,
                           outages=[(start + 10 ** 15, start + 10 ** 15 + 3 * 86400 * 10 ** 9)])
    write_series_csv(path, t, v, utc_offset_h=9)


def main(n: int = 800_000, *, repeat: int = 3) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"camera_{n}.csv"
    make_file(path, n)
    print(f"{path.name}: ~{n:,} rows of 1-minute samples; best of {repeat} fresh processes")
    base = measure("import pandas as pd",
                   f"df = pd.read_csv({str(path)!r}, comment='#'); t = pd.to_datetime(df.iloc[:, 0], utc=True, "
                   "format='ISO8601')", repeat=repeat)
    ours = measure("from vision.series import read_camera_series", f"s = read_camera_series({str(path)!r})",
                   repeat=repeat)
    print(row("pandas.read_csv + to_datetime (no checks)", base))
    print(row("BridgeSurvey read_camera_series", ours, base))
    print(f"  RESULT: {ours['seconds']:.2f} s for {n:,} rows ({n / ours['seconds'] / 1e3:.0f} k rows/s), "
          f"x{ours['seconds'] / base['seconds']:.2f} the plain pandas read; peak {ours['peak_mb']:.0f} MiB")
    figures(rows=n, seconds=ours["seconds"], ratio_to_pandas=ours["seconds"] / base["seconds"],
            peak_mb=ours["peak_mb"])


if __name__ == "__main__":
    _small, _args = small_mode()
    main(int(_args[0]) if _args else 20_000 if _small else 800_000, repeat=1 if _small else 3)

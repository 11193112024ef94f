"""Accuracy of 'analyse' (issue 15): 30 random simulated campaigns with a known thermal coefficient, event
steps and creep coefficients; share of recovered values within 2 sigma of the truth, and |error|/sigma.

Each campaign: weekly epochs over 650 days, each scanned at a random time between 08:00 and 16:00; an
hourly air temperature with a seasonal swing of +-12 degC and a daily one of +-4 degC; the deck follows the
temperature averaged over a random window (3-24 h) with a random coefficient (0.05-0.3 mm/degC); two
construction events (day 144: 3-8 mm, day 333: 1-3 mm) each followed by creep of coefficient 0.8-2.0; the
epochs carry the processing's sigma (0.1 mm) while the actual scatter is 0.08-0.25 mm, plus a sun term
the model does not know (up to 0.15 mm, from the time of day).

Two creep laws generate the truth: the model's own (ACI 209 time shape, time parameter 10-60 days) and a
different one (exponential, 1 - exp(-t / 60 d)), to show what a wrong creep law costs.

Usage: ``./run bench analysis_accuracy [N]`` (``--small``: 4 campaigns a law). This runs at the level of
displacement histories: the
simulated scans behind each epoch are what the LiDAR benches measure.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from _harness import figures, small_mode, write_figure

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


from projects.analysis.models import Event, creep_shape, effective_temperature, fit_target  # noqa: E402


def campaign(rng, law_name: str):
    days = 650
    th = np.arange(0, days, 1 / 24)
    temp = 10 - 12 * np.cos(2 * np.pi * (th - 15) / 365.25) + 4 * np.sin(2 * np.pi * (th % 1 - 0.4)) \
        + rng.normal(0, 0.6, th.size)
    te = np.arange(3, days, 7) + rng.uniform(8, 16, np.arange(3, days, 7).size) / 24
    window = rng.choice((3.0, 6.0, 12.0, 24.0))
    b = rng.uniform(0.05, 0.3)
    teff = effective_temperature(te, th, temp, window, 0.0)
    truth = {"b": b, "s1": -rng.uniform(3, 8), "s2": -rng.uniform(1, 3), "phi1": rng.uniform(0.8, 2.0),
             "phi2": rng.uniform(0.8, 2.0)}  # final creep coefficients; replaced by the developed ones below
    d_creep = rng.uniform(10, 60)
    d = b * (teff - np.median(teff))
    for key, t0, s, phi in (("phi1", 144.0, truth["s1"], truth["phi1"]), ("phi2", 333.0, truth["s2"], truth["phi2"])):
        tau = te - t0
        law = (lambda x: creep_shape(x, d_creep)) if law_name == "model" else \
            (lambda x: 1 - np.exp(-np.clip(x, 0, None) / 60.0))
        d = d + (tau >= 0) * (s + phi * s * law(tau))
        truth[key] = phi * float(law(te[-1] - t0))  # the creep coefficient developed by the last epoch
    sun = rng.uniform(0, 0.15) * np.sin(np.pi * np.clip((te % 1) * 24 - 8, 0, 8) / 8)
    d = d + sun + rng.normal(0, rng.uniform(0.08, 0.25), te.size)
    fit = fit_target(te, d, np.full(te.size, 0.1), temperature=(th, temp),
                     events=[Event(144.0, "e1"), Event(333.0, "e2")])
    e1, e2 = sorted(fit.events, key=lambda e: e.label)
    est = {"b": (fit.thermal_mm_per_degC, fit.thermal_sigma), "s1": (e1.step_mm, e1.step_sigma_mm),
           "s2": (e2.step_mm, e2.step_sigma_mm), "phi1": (e1.creep_coefficient, e1.creep_coefficient_sigma),
           "phi2": (e2.creep_coefficient, e2.creep_coefficient_sigma)}
    return truth, est


NAMES = {"b": "thermal coefficient (mm/degC)", "s1": "step of event 1 (mm)", "s2": "step of event 2 (mm)",
         "phi1": "creep coefficient of event 1 (developed by the last epoch)",
         "phi2": "creep coefficient of event 2 (developed by the last epoch)"}


#: The documentation's column for each quantity, and its row for each creep law of the truth.
COLUMNS = {"b": "thermal coefficient", "s1": "step 1", "s2": "step 2", "phi1": "creep coefficient 1",
           "phi2": "creep coefficient 2"}
LAWS = {"model": "ACI 209 shape (time parameter 10–60 d)", "exponential": "exponential, 60 d"}


def main(n: int = 30, seed: int = 15):
    lines = ["| truth's creep law | " + " | ".join(COLUMNS.values()) + " | all |", "|---" * (len(COLUMNS) + 2) + "|"]
    ratios = []
    found = {}
    for law in ("model", "exponential"):
        rng = np.random.default_rng(seed)
        z = {k: [] for k in NAMES}
        err = {k: [] for k in NAMES}
        for _ in range(n):
            truth, est = campaign(rng, law)
            for k in NAMES:
                v, s = est[k]
                if np.isfinite(v) and np.isfinite(s) and s > 0:
                    z[k].append((v - truth[k]) / s)
                    err[k].append(v - truth[k])
        label = "the model's own creep law" if law == "model" else "a different creep law (exponential, 60 d)"
        print(f"\n{n} campaigns, truth from {label}:")
        print("| quantity | within 2 sigma | RMS error | RMS |error|/sigma |")
        print("|---|---|---|---|")
        allz = []
        for k, name in NAMES.items():
            zz = np.abs(np.array(z[k]))
            allz += list(zz)
            ratios.append(np.sqrt(np.mean(zz ** 2)))
            print(f"| {name} | {np.mean(zz <= 2) * 100:.0f} % ({len(zz)}) | {np.sqrt(np.mean(np.square(err[k]))):.3f} | "
                  f"{np.sqrt(np.mean(zz ** 2)):.2f} |")
        print(f"| all | {np.mean(np.array(allz) <= 2) * 100:.0f} % | | |")
        found[f"{law}_within_2sigma"] = float(np.mean(np.array(allz) <= 2))
        found[f"{law}_thermal_rms_error"] = float(np.sqrt(np.mean(np.square(err["b"]))))
        found[f"{law}_estimates"] = len(allz)
        lines.append(f"| {LAWS[law]} | " + " | ".join(f"{np.mean(np.abs(np.array(z[k])) <= 2):.0%}" for k in COLUMNS)
                     + f" | {np.mean(np.array(allz) <= 2):.0%} |")
    write_figure("analysis_accuracy", "\n".join(lines),
                 notes=f"Share of the {n} recovered values within 2σ of the truth; RMS |error|/σ "
                       f"{min(ratios):.2f}–{max(ratios):.2f}.")
    figures(campaigns=n, **found)


if __name__ == "__main__":
    _small, _args = small_mode()
    main(*(tuple(int(a) for a in _args[:1]) or ((4,) if _small else ())))

"""Benchmark of every identification mode's new terms (issue 38 item 5): model choice, interval
coverage, terms at zero when not needed, shape verdicts and time, over many seeds.

1. Friction sweep: 10 |speeds| 0.05..100 rad/s, each twice per direction (40 rows, shuffled),
   noise 2e-4 N*m (1 % of Fc). Symmetric truth (Fc 0.02, Fs 0.03, vs 1, sigma2 1e-4) and
   asymmetric truth (- direction: Fc 0.026, Fs 0.034, vs 1.5, sigma2 1.3e-4): how often each
   law is chosen, how often the per-direction differences hold 0 (symmetric data), interval
   coverage of the truths, the shape verdicts, median time.
2. Torque-twist: a growing chirp of twist (2 s at 1 kHz), kL 590, alpha 3 mrad, c 0.5, offset
   1 mrad, noise 0.05 N*m; data without friction or preload fitted with offset, friction,
   preload (are Ft and preload zero within their intervals?) and data with Ft = 0.8 N*m,
   preload 1.5 N*m (coverage of every truth); Eq. 8 alone on the friction data: its kL bias and
   its shape verdict; median time.

Run: ``.venv/bin/python experiments/bench_idmodes.py [--seeds N]`` (default 50).
"""

from __future__ import annotations

import statistics
import sys
import time
from collections import Counter

import numpy as np

from ema_cli.identify.friction.sweep import SweepData, fit_friction_sweep, sweep_adequacy
from ema_cli.identify.torque.terms import fit_terms

SPEEDS = np.geomspace(0.05, 100.0, 10)
SYM = dict(Fc=0.02, Fs=0.03, vs=1.0, sigma2=1e-4)
ASYM = dict(SYM, Fc_neg=0.026, Fs_neg=0.034, vs_neg=1.5, sigma2_neg=1.3e-4)


def sweep(p: dict[str, float], seed: int) -> SweepData:
    rng = np.random.default_rng(seed)
    w = np.concatenate([SPEEDS, SPEEDS, -SPEEDS, -SPEEDS])
    rng.shuffle(w)
    neg = {**p, **{k[:-4]: v for k, v in p.items() if k.endswith("_neg")}}
    u = np.abs(w)

    def lev(q: dict[str, float]) -> np.ndarray:
        return q["Fc"] + (q["Fs"] - q["Fc"]) * np.exp(-u / q["vs"]) + q["sigma2"] * u

    T = np.where(w > 0, lev(p), -lev(neg)) + 2e-4 * rng.standard_normal(w.size)
    return SweepData(w, T, f"seed {seed}")


def friction(seeds: int) -> None:
    for name, truth in (("symmetric", SYM), ("asymmetric", ASYM)):
        chosen, verdict, sym_verdict = Counter(), Counter(), Counter()
        zero_diff, cover, n_cover, times = 0, 0, 0, []
        for s in range(seeds):
            t0 = time.perf_counter()
            fit = fit_friction_sweep(sweep(truth, s))
            times.append(time.perf_counter() - t0)
            chosen[fit.chosen] += 1
            verdict[fit.adequacy.verdict] += 1
            sym_verdict[sweep_adequacy(fit.data, fit.laws["stribeck"]).verdict] += 1
            diffs = fit.laws["stribeck-dir"].differences()
            zero_diff += sum(d["zero_inside"] for d in diffs.values())
            law = fit.laws["stribeck-dir" if name == "asymmetric" else "stribeck"]
            full = {**truth, **{f"{k}_neg": v for k, v in truth.items() if k in SYM
                                and f"{k}_neg" not in truth}}
            tv = np.array([full[n] for n in law.names])
            u = law.uncertainty
            cover += int(np.sum((u.ci_low <= tv) & (tv <= u.ci_high)))
            n_cover += tv.size
        print(f"friction, {name} data, {seeds} seeds: chosen {dict(chosen)}; shape of the "
              f"chosen law {dict(verdict)}; of the symmetric Stribeck law {dict(sym_verdict)}")
        which = "per-direction" if name == "asymmetric" else "symmetric"
        print(f"  per-direction differences holding 0: {zero_diff}/{4 * seeds}; truth inside "
              f"the 95 % intervals of the {which} law: {cover}/{n_cover}; median time "
              f"{statistics.median(times):.3f} s")


def twist() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 2.0, 2001)
    ph = 2 * np.pi * (0.5 * t + 0.8 * t**2)
    env = 0.01 + 0.005 * t
    return t, env * np.sin(ph), 0.005 * np.sin(ph) + env * np.cos(ph) * 2 * np.pi * (0.5 + 1.6 * t)


def torque(seeds: int) -> None:
    t, dth, dw = twist()
    d = dth - 1e-3
    base = 590.0 * np.sign(d) * np.maximum(np.abs(d) - 3e-3, 0) + 0.5 * dw
    hyst = base + 0.8 * np.sign(dw) + 1.5 * np.clip(d / 3e-3, -1, 1)
    terms = ("offset", "friction", "preload")
    zero, cover, n_cover, times, bias, v8, vt = 0, 0, 0, [], [], Counter(), Counter()
    truth = {"kL": 590.0, "alpha": 3e-3, "c": 0.5, "dth0": 1e-3, "Ft": 0.8, "preload": 1.5}
    for s in range(seeds):
        rng = np.random.default_rng(s)
        T0 = base + 0.05 * rng.standard_normal(t.size)
        iv = fit_terms(t, dth, dw, T0, "paper", 0.0, True, 0.0, terms, (0.0, 0.006)).intervals()
        zero += iv["Ft"]["zero_inside"] + iv["preload"]["zero_inside"]
        T1 = hyst + 0.05 * rng.standard_normal(t.size)
        t0 = time.perf_counter()
        f = fit_terms(t, dth, dw, T1, "paper", 0.0, True, 0.0, terms, (0.0, 0.006))
        times.append(time.perf_counter() - t0)
        iv = f.intervals()
        for n, v in truth.items():
            cover += iv[n]["ci95"][0] <= v <= iv[n]["ci95"][1]
            n_cover += 1
        vt[f.adequacy.verdict] += 1
        plain = fit_terms(t, dth, dw, T1, "paper", 0.0, True, 0.0, (), (0.0, 0.006))
        bias.append(100 * (plain.params["kL"] / 590.0 - 1))
        v8[plain.adequacy.verdict] += 1
    print(f"torque-twist, {seeds} seeds: Ft and preload zero within their intervals on data "
          f"without them: {zero}/{2 * seeds}; truth inside the intervals with terms: "
          f"{cover}/{n_cover}; shape with terms {dict(vt)}; median time "
          f"{statistics.median(times):.3f} s")
    print(f"  Eq. 8 alone on the friction data: kL bias median {statistics.median(bias):+.2f} % "
          f"(range {min(bias):+.2f} .. {max(bias):+.2f} %); shape {dict(v8)}")


if __name__ == "__main__":
    n = int(sys.argv[sys.argv.index("--seeds") + 1]) if "--seeds" in sys.argv else 50
    friction(n)
    torque(n)

"""Benchmark of the log identifications (issue 13): accuracy, interval coverage and time.

Everything at the model's defaults (the `contact` damping form with its damping ramp,
``contact_tau`` = 1e-4 s), as ``ema identify --make-data closed-loop`` and ``--closed-loop``
run without options:

1. Closed loop, default free set (kL, alpha, Fc, sigma2) and default budget, on 4 s synthetic
   logs, 1 % noise, seeds 0..9: errors vs the truth, 95 % interval coverage, wall time
   (median) and the kernel throughput in the GA.
2. The same, noise-free (seed 0): error of the polished optimum (target 1e-4 relative), of the
   GA's optimum (first second, coarse step) and of each polish stage.
3. Fs, vs and sigma0 freed as well (1 % noise, seed 0): what the tool reports about them.
4. What each part does: the jump form (``contact_tau`` = 0, data and fit) and the `paper`
   damping form (seed 0, 1 % noise); the GA on the whole log (``ga_horizon_s`` = null) vs
   the continuation, noise-free log, GA seeds 0..9.
5. Friction sweep, 1 % noise, seeds 0..9 (and 200 seeds for the bias): mean error, coverage.
6. The GA's coarse step: the least-squares optimum of a noise-free log (data at 1e-5 s)
   simulated at 2e-5, 5e-5 and 1e-4 s: its bias against the truth.

Run: ``NUMBA_NUM_THREADS=2 .venv/bin/python experiments/bench_identify_logs.py [--quick]``.
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from ema_cli.identify.closed_loop.ga_fit import build_problem, polish, run_closed_loop
from ema_cli.identify.closed_loop.problem import CHANNELS, ClosedLoopLog
from ema_cli.identify.friction.sweep import SWEEP_NAMES, SweepData, fit_friction_sweep
from ema_cli.identify.log_settings import ClosedLoopSettings
from ema_cli.identify.make_data import closed_loop_log, friction_sweep_log
from ema_cli.units import DEG, RPM


def as_log(syn) -> ClosedLoopLog:
    c = syn.columns
    return ClosedLoopLog(c["t_s"], c["theta_ref_deg"] * DEG,
                         {k: c[k] * CHANNELS[k][1] for k in CHANNELS}, "synthetic", 0.0,
                         syn.truth)


def closed_loop(seeds: range, noise: float, plant: dict | None = None, **over) -> list:
    """Fit synthetic logs made with ``plant`` (the same plant fixed in the fit)."""
    plant = plant or {}
    out = []
    for seed in seeds:
        syn = closed_loop_log(plant, noise, seed)
        settings = ClosedLoopSettings(plant=plant, **over)
        t0 = time.perf_counter()
        fit = run_closed_loop(settings, as_log(syn))
        wall = time.perf_counter() - t0
        js = fit.to_json()
        out.append((fit, js, wall))
        err = ", ".join(f"{n} {e:+.3g} %" for n, e in js["error_pct_vs_truth"].items())
        cov = ", ".join(f"{n} {'in' if v else 'OUT'}" for n, v in js["truth_in_ci95"].items())
        nd = js["not_determined"]
        print(f"  seed {seed}: {wall:5.1f} s (GA {fit.timings['ga_s']:.1f} s at "
              f"{fit.ga_throughput / 1e6:4.1f} M steps/s, polish {fit.timings['polish_s']:.1f} "
              f"s); error {err}; CI95 {cov}" + (f"; NOT DETERMINED {nd}" if nd else ""),
              flush=True)
    return out


def summary(res: list, n: int) -> None:
    names = res[0][0].names
    for nm in names:
        errs = [abs(js["error_pct_vs_truth"][nm]) for _, js, _ in res]
        covered = sum(js["truth_in_ci95"][nm] for _, js, _ in res)
        rse = [100 * js["parameters"][nm]["relative_se"] for _, js, _ in res]
        print(f"   {nm:7s} |error| max {max(errs):.3g} %, mean {np.mean(errs):.3g} %; "
              f"relative SE median {statistics.median(rse):.3g} %; CI95 covers the truth in "
              f"{covered}/{n}")
    walls = [w for _, _, w in res]
    print(f"   wall time median {statistics.median(walls):.1f} s (min {min(walls):.1f}, max "
          f"{max(walls):.1f}); GA kernel throughput median "
          f"{statistics.median(f.ga_throughput for f, _, _ in res) / 1e6:.1f} M steps/s")


def main(quick: bool) -> None:
    n = 3 if quick else 10
    print(f"1. closed loop, defaults, 1 % noise, seeds 0..{n - 1}")
    res = closed_loop(range(n), 1.0)
    summary(res, n)

    print("2. closed loop, defaults, noise-free, seed 0")
    (fit, js, _), = closed_loop(range(1), 0.0)
    truth = fit.problem.log.truth
    ga_err = {nm: 100 * (fit.x_ga[j] / truth[nm] - 1) for j, nm in enumerate(fit.names)}
    print(f"   GA optimum (first {fit.horizons[0]:g} s, at ga_dt): " + ", ".join(
        f"{k} {v:+.3g} %" for k, v in ga_err.items()))
    for st in fit.stages:
        print(f"   polish on {st['horizon_s']:g} s ({st['jacobian_evaluations']} Jacobians, "
              f"{st['wall_time_s']:.1f} s): " + ", ".join(
                  f"{k} {100 * (v / truth[k] - 1):+.3g} %" for k, v in st["x"].items()))
    worst = max(abs(e) for e in js["error_pct_vs_truth"].values()) / 100
    print(f"   max relative error {worst:.2g}")

    print("3. Fs, vs, sigma0 freed as well (1 % noise, seed 0)")
    free = {"kL": (300, 900), "alpha": (0, 0.01), "Fc": (0, 0.1), "sigma2": (0, 0.1),
            "Fs": (0, 0.2), "vs": (0.01, 10), "sigma0": (1, 200)}
    (fit, js, _), = closed_loop(range(1), 1.0, free=free)
    for nm, v in js["parameters"].items():
        why = "; ".join(v["not_determined_because"])
        print(f"   {nm:7s} {v['value']:.6g} ± {v['standard_error']:.3g} {v['unit']} "
              f"(rel SE {100 * (v['relative_se'] or np.nan):.3g} %), "
              + ("determined" if v["determined"] else f"NOT DETERMINED: {why}"))
    corr = fit.uncertainty.corr
    big = [(a, b, corr[i, k]) for i, a in enumerate(fit.names) for k, b in enumerate(fit.names)
           if k > i and abs(corr[i, k]) > 0.8]
    print("   |corr| > 0.8: " + (", ".join(f"{a}-{b} {c:+.3f}" for a, b, c in big) or "none"))

    print("4. what each part does (seed 0)")
    for label, plant in (("jump form (contact_tau = 0), 1 % noise", {"contact_tau": 0.0}),
                         ("paper damping form, 1 % noise", {"damping": "paper"})):
        print(f"   {label}:")
        (fit, js, _), = closed_loop(range(1), 1.0, plant)
        print("     quadratic check (1 for a smooth cost): " + ", ".join(
            f"{k} {v:.3g}" for k, v in js["quadratic_check"].items() if v is not None))
    syn = closed_loop_log({}, 0.0, 0)
    for horizon in (None, 1.0):
        print(f"   noise-free log, GA seeds 0..{n - 1}, ga_horizon_s = {horizon}:")
        right, walls = 0, []
        for seed in range(n):
            t0 = time.perf_counter()
            fit = run_closed_loop(ClosedLoopSettings(seed=seed, ga_horizon_s=horizon),
                                  as_log(syn))
            walls.append(time.perf_counter() - t0)
            e = fit.to_json()["error_pct_vs_truth"]
            ok = abs(e["kL"]) < 0.5 and abs(e["alpha"]) < 0.5
            right += ok
            print(f"     GA seed {seed}: {walls[-1]:5.1f} s, " + ("the truth" if ok else
                  "ANOTHER VALLEY: " + ", ".join(f"{k} {v:+.3g} %" for k, v in e.items())),
                  flush=True)
        print(f"     right {right}/{n}, wall time median {statistics.median(walls):.1f} s")

    print("5. friction sweep, 1 % noise, seeds 0..9 and 0..199")
    for count in (10, 200):
        errs, cover, walls = [], [], []
        for seed in range(count):
            syn = friction_sweep_log({}, 1.0, seed)
            tv = np.array([syn.truth[k] for k in SWEEP_NAMES])
            t0 = time.perf_counter()
            f = fit_friction_sweep(SweepData(syn.columns["omega_rpm"] * RPM,
                                             syn.columns["torque_nm"], "synthetic"))
            walls.append(time.perf_counter() - t0)
            errs.append(100 * (f.x / tv - 1))
            u = f.uncertainty
            cover.append((u.ci_low <= tv) & (tv <= u.ci_high))
        e, c = np.array(errs), np.array(cover)
        print(f"   {count} seeds: mean error " + ", ".join(
            f"{k} {m:+.3g} % (sd {s:.3g} %, SE of the mean {s / np.sqrt(count):.2g} %)"
            for k, m, s in zip(SWEEP_NAMES, e.mean(0), e.std(0, ddof=1), strict=True))
            + "; CI95 coverage " + ", ".join(f"{k} {int(v)}/{count}" for k, v in
                                              zip(SWEEP_NAMES, c.sum(0), strict=True))
            + f"; median fit {statistics.median(walls) * 1e3:.0f} ms")

    print("6. the GA's step: optimum of the noise-free log (defaults) simulated coarser")
    syn = closed_loop_log({}, 0.0, 0)
    for ga_dt in (2e-5, 5e-5, 1e-4):
        prob, _ = build_problem(ClosedLoopSettings(dt_s=ga_dt, ga_dt_s=ga_dt), as_log(syn))
        xt = np.array([syn.truth[k] for k in prob.names])
        res, _ = polish(prob, xt, 30)
        print(f"   dt {ga_dt:g} s: optimum bias " + ", ".join(
            f"{k} {100 * (v / t - 1):+.3f} %" for k, v, t in zip(prob.names, res.x, xt,
                                                                 strict=True)))


if __name__ == "__main__":
    main("--quick" in sys.argv)

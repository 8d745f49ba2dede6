"""Benchmark and acceptance figures of ``ema sensitivity`` on configs/sensitivity.yaml (issue 12).

1. Time: Sobol at n = 4096 (no second order) for each input on its own, every sample computed
   (no job cache), the kernel already compiled: wall time of ``compute_sensitivity`` (sampling,
   sweep plan, kernel, analysis with convergence), with its parts; medians over ``--repeats``.
   Goal: under 2 minutes per input on 2 cores.
2. The indices of the last repeat: the largest ST confidence half-width (goal < 0.05; the
   bootstrap's, with the config's resamples, and beside it the asymptotic (delta-method)
   half-width the bootstrap approaches, free of resampling scatter), the dummy factor's ST
   (goal < 0.02), and the largest half-width for the untransformed metrics (the runs are the
   same; only the analysis differs).
3. Morris (``--morris-n`` trajectories) on the same factors: Spearman rank correlation of mu*
   with Sobol ST per input and metric (goal >= 0.8).

Usage: ``python experiments/bench_sensitivity.py [--repeats N] [--n 4096] [--morris-n 256]
[--inputs step0.1,step20]``. Prints one line per figure and a JSON summary at the end.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from ema_cli.config.loader import load_config
from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.sensitivity.analyze import indices, sobol_conf_asymptotic, spearman
from ema_cli.sensitivity.run import compute_sensitivity, transformed
from ema_cli.sweep.execute import cpu_count

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "sensitivity.yaml"
GOAL_WALL_S = 120.0  # per input [s]
GOAL_CONF = 0.05  # largest ST confidence half-width [-]
GOAL_DUMMY = 0.02  # ST of the dummy factor [-]
GOAL_SPEARMAN = 0.8  # Morris mu* vs Sobol ST rank correlation [-]


def one_input(cfg: SensitivityConfig, name: str) -> SensitivityConfig:
    """The config with only input ``name``."""
    data = cfg.model_dump(mode="json")
    data["inputs"] = [i for i in data["inputs"] if i["name"] == name]
    return SensitivityConfig.model_validate(data)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n", type=int, default=4096)
    ap.add_argument("--morris-n", type=int, default=256)
    ap.add_argument("--inputs", default="")
    args = ap.parse_args(argv)
    cfg = load_config(CONFIG, (), SensitivityConfig)
    names = [n for n in args.inputs.split(",") if n] or [n for n, _ in cfg.input_list()]
    print(f"bench_sensitivity: {CONFIG.name}, {len(cfg.factors)} factors, Sobol n = {args.n}, "
          f"{cpu_count()} cores, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS')}, "
          f"load average {os.getloadavg()[0]:.2f}")
    # compile/load the kernel once, outside the timings
    compute_sensitivity(one_input(cfg, names[0]), "sobol", 1, progress=False)
    summary: dict[str, Any] = {"n": args.n, "factors": len(cfg.factors), "inputs": {}}
    for name in names:
        c = one_input(cfg, name)
        walls, parts, cpus = [], [], []
        res = None
        for k in range(args.repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            res = compute_sensitivity(c, "sobol", args.n, progress=False)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            parts.append(res.timings)
            print(f"  {name} repeat {k + 1}: {walls[-1]:.1f} s (kernel "
                  f"{res.timings[f'{name}.kernel']:.1f} s, plan {res.timings[f'{name}.plan']:.1f}"
                  f" s, analysis {res.timings[f'{name}.analysis']:.1f} s; CPU {cpus[-1]:.1f} s "
                  f"over all threads), load "
                  f"{os.getloadavg()[0]:.2f}", flush=True)
        assert res is not None
        med = statistics.median(walls)
        part_med = {p: statistics.median(t[f"{name}.{p}"] for t in parts)
                    for p in ("plan", "kernel", "analysis")}
        part_med["sample+validate"] = statistics.median(t["sample"] for t in parts)
        runs = res.design.n_rows
        ix = res.indices
        worst = float(ix["ST_conf"].max())
        at = ix.loc[ix["ST_conf"].idxmax()]
        asym = max(float(sobol_conf_asymptotic(
            transformed(res.inputs[0].values(m), cfg.sensitivity.transform), res.design.d,
            cfg.sensitivity.conf_level)[1].max()) for m in cfg.metrics)
        dummy = float(ix[ix["factor"] == "dummy"]["ST"].abs().max())
        raw = []
        for metric in cfg.metrics:
            t = indices(res.design, res.inputs[0].values(metric), cfg.sensitivity.conf_level,
                        cfg.sensitivity.num_resamples, cfg.seed)
            raw.append(float(t["ST_conf"].max()))
        morris = compute_sensitivity(c, "morris", args.morris_n, progress=False)
        rho = {}
        for metric in cfg.metrics:
            s = ix[ix["metric"] == metric].set_index("factor")["ST"]
            mi = morris.indices
            m = mi[mi["metric"] == metric].set_index("factor")["mu_star"]
            rho[metric] = spearman(m.loc[s.index].to_numpy(), s.to_numpy())
        print(f"{name}: {runs:,} runs, wall median {med:.1f} s (goal < {GOAL_WALL_S:.0f} s: "
              f"{'met' if med < GOAL_WALL_S else 'NOT met'}); parts (medians) "
              + ", ".join(f"{k} {v:.1f} s" for k, v in part_med.items())
              + f"; CPU {statistics.median(cpus):.1f} s (all threads; {cpu_count()} idle cores "
                f"would take >= {statistics.median(cpus) / cpu_count():.1f} s)")
        print(f"{name}: largest ST half-width {worst:.4f} ({at['factor']}, {at['metric']}; "
              f"bootstrap, {cfg.sensitivity.num_resamples} resamples; goal < {GOAL_CONF}: "
              f"{'met' if worst < GOAL_CONF else 'NOT met'}), asymptotic {asym:.4f}; "
              f"dummy ST {dummy:.2e} (goal < "
              f"{GOAL_DUMMY}); untransformed metrics: largest ST half-width "
              f"{max(raw):.4f}")
        print(f"{name}: Spearman(Morris mu*, Sobol ST) "
              + ", ".join(f"{k} {v:.3f}" for k, v in rho.items())
              + f" (goal >= {GOAL_SPEARMAN}; Morris {morris.design.n_rows:,} runs)")
        print(ix[["metric", "factor", "ST", "ST_conf", "S1", "S1_conf"]].round(4).to_string())
        summary["inputs"][name] = {
            "runs": runs, "walls_s": walls, "wall_median_s": med, "cpu_s": cpus,
            "parts_median_s": part_med,
            "max_st_conf": worst, "max_st_conf_at": [at["metric"], at["factor"]],
            "max_st_conf_asymptotic": asym,
            "max_st_conf_untransformed": max(raw), "dummy_st": dummy,
            "spearman": rho, "morris_runs": morris.design.n_rows,
            "ranking_st": {m: ix[ix["metric"] == m].sort_values("ST", ascending=False)[
                "factor"].tolist() for m in cfg.metrics}}
    print(json.dumps(summary, default=float))
    return summary


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

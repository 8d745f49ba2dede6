"""Do the Sobol bootstrap half-widths describe the real scatter of the indices? (issue 12)

The bootstrap of ``ema sensitivity`` resamples the N base samples as if they were independent;
they are points of one scrambled Sobol' sequence (randomised quasi-Monte Carlo), whose estimates
may scatter less (or, for rough outputs, not). This check runs the Sobol design of
configs/sensitivity.yaml on one input for several seeds (independent scramblings) at a smaller
N and compares, per factor and metric, 1.96 x the standard deviation of ST over the seeds with
the mean asymptotic (delta-method) half-width, the limit of the bootstrap's. A ratio near 1: the
half-widths are honest; below 1: conservative. With S seeds the scatter itself is known to
about +-1/sqrt(2(S-1)) (25 % for 9 seeds).

Not part of ``make bench`` (S x N x 12 runs: about 10 min for 8 seeds at N = 1024 on 2 cores).
Usage: ``python experiments/sensitivity_scatter.py [--n 1024] [--seeds 0,101,...,108]
[--input step0.1]``. Prints one line per factor and metric.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ema_cli.config.loader import load_config
from ema_cli.config.sensitivity import SensitivityConfig
from ema_cli.sensitivity.analyze import sobol_conf_asymptotic, sobol_indices
from ema_cli.sensitivity.run import compute_sensitivity, transformed

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "sensitivity.yaml"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1024)
    ap.add_argument("--seeds", default="0,101,102,103,104,105,106,107,108")
    ap.add_argument("--input", default="step0.1")
    args = ap.parse_args(argv)
    cfg = load_config(CONFIG, (), SensitivityConfig)
    seeds = [int(s) for s in args.seeds.split(",")]
    s = cfg.sensitivity
    st: dict[str, list[np.ndarray]] = {m: [] for m in cfg.metrics}
    hw: dict[str, list[np.ndarray]] = {m: [] for m in cfg.metrics}
    names: list[str] = []
    for seed in seeds:
        data = cfg.model_dump(mode="json")
        data["inputs"] = [i for i in data["inputs"] if i["name"] == args.input]
        data["seed"] = seed
        res = compute_sensitivity(SensitivityConfig.model_validate(data), "sobol", args.n)
        names = [f.name for f in res.design.factors]
        for m in cfg.metrics:
            y = transformed(res.inputs[0].values(m), s.transform)
            st[m].append(sobol_indices(y, res.design.d, s.conf_level, 200, 1)[2])
            hw[m].append(sobol_conf_asymptotic(y, res.design.d, s.conf_level)[1])
        print(f"seed {seed}: {res.design.n_rows:,} runs", flush=True)
    print(f"{args.input}, N = {args.n}, {len(seeds)} seeds: 1.96 sd(ST over seeds) vs the mean "
          "asymptotic half-width")
    for m in cfg.metrics:
        a, h = np.array(st[m]), np.array(hw[m])
        for j, name in enumerate(names):
            if h[:, j].mean() < 1e-3:
                continue
            sd = 1.96 * a[:, j].std(ddof=1)
            print(f"  {m:16s} {name:12s} ST {a[:, j].mean():.3f}  1.96 sd {sd:.4f}  half-width "
                  f"{h[:, j].mean():.4f}  ratio {sd / h[:, j].mean():.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""`make bench`: `ema tune configs/tune.yaml` at its default budget, in process (warm kernel).

Prints the median wall time of REPEATS runs after a warm-up, the kernel throughput inside the
tuning and the tuned cost (issue 11's goal: the default budget in under 60 s on 2 cores).
``--seeds N`` also runs N seeds and prints the spread of their costs (goal: within 2 %), and
``--de`` runs scipy's differential evolution at the same budget (goal: within 5 % of the GA).
Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

from ema_cli.config.loader import load_config
from ema_cli.config.tune import TuneConfig
from ema_cli.tune.problem import build_scenarios
from ema_cli.tune.run import min_budget, run_tuning

REPEATS = 3
ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "tune.yaml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=0, help="also run this many seeds")
    ap.add_argument("--de", action="store_true", help="also run DE at the same budget")
    ap.add_argument("--repeats", type=int, default=REPEATS)
    args = ap.parse_args()
    cfg = load_config(CONFIG, [], TuneConfig)
    scenarios, _ = build_scenarios(cfg, CONFIG.parent)
    threads = os.environ.get("NUMBA_NUM_THREADS", "all")
    print(f"\n== ema tune configs/tune.yaml (numba threads: {threads}; median of "
          f"{args.repeats} after a warm-up)")
    o = cfg.optimiser  # warm-up (load the kernels): the smallest budget it accepts
    run_tuning(cfg, scenarios, budget=min_budget(o.method, o.pop, len(cfg.variables), o.polish))
    walls, outs = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        outs.append(run_tuning(cfg, scenarios))
        walls.append(time.perf_counter() - t0)
    o = outs[-1]
    steps = (o.timings["evaluations"] * len(scenarios) * round(cfg.simulation.duration_s
                                                               / cfg.simulation.dt_s))
    print(f"  default budget ({int(o.timings['evaluations'])} evaluations x {len(scenarios)} "
          f"scenarios): {statistics.median(walls):6.1f} s   (goal < 60 s; runs "
          f"{', '.join(f'{w:.1f}' for w in walls)} s)")
    print(f"  kernel {o.timings['kernel_s']:.1f} s ({steps / o.timings['kernel_s'] / 1e6:.1f} M "
          f"lane-steps/s), margins {o.timings['margins_s']:.1f} s; tuned cost "
          f"{float(o.after.cost[0]):.4f} (default controller 1)")
    if args.seeds:
        t0 = time.perf_counter()
        s = run_tuning(cfg, scenarios, runs=args.seeds)
        costs = [r.cost for r in s.runs]
        print(f"  {args.seeds} seeds: costs {min(costs):.4f} .. {max(costs):.4f}, spread "
              f"{100 * s.cost_spread:.2f} % (goal < 2 %), {time.perf_counter() - t0:.0f} s")
    if args.de:
        d = run_tuning(cfg, scenarios, method="de")
        ga, de = float(o.after.cost[0]), float(d.after.cost[0])
        print(f"  DE at the same budget: {de:.4f} vs GA {ga:.4f} "
              f"({100 * (de / ga - 1):+.2f} %; goal within 5 %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""`make bench`: `ema yield` of the bundled battery (configs/acceptance.yaml) over the bundled
tolerances (configs/tolerances.yaml): 200 and 1,000 units (issue 23's goals: under 2 and 10
minutes on 2 idle cores), the kernel throughput inside, and the worst-case search after the
largest run (its time reported apart from the units').

In process, the kernel compiled and warm (one 16-unit warm-up), NUMBA_NUM_THREADS as `make
bench` sets it. Walls are medians of REPEATS runs (1 for 1,000 units: ~25 min); the kernel's
throughput is the units' lane-steps (cases x integration steps, ``sim.runner.TALLY``, kept
in the run's timings) per second inside the compiled kernel, and per second of the run's
wall. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

from ema_cli.api.production import production_yield

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "configs" / "acceptance.yaml"
TOL = ROOT / "configs" / "tolerances.yaml"


def _run(n: int, worst: int | None = None, out: Path | None = None):
    t0 = time.perf_counter()
    res = production_yield(SPEC, TOL, n=n, seed=0, block=100, worst_budget=worst)
    wall = time.perf_counter() - t0 - res.timings.get("worst_case_s", 0.0)
    if out is not None:
        res.save(out)
    return wall, res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", default="200,1000", help="units per run, comma-separated")
    ap.add_argument("--repeats", type=int, default=3, help="runs of the smaller sizes")
    ap.add_argument("--worst", type=int, default=48,
                    help="worst-case budget per test (the largest size's run)")
    ap.add_argument("--out", type=Path, default=None,
                    help="save the largest size's run here (REPRODUCTION.md quotes it)")
    args = ap.parse_args()
    threads = os.environ.get("NUMBA_NUM_THREADS", "all")
    print(f"\n== ema yield: {SPEC.name} x {TOL.name} (numba threads: {threads})")
    _run(16)
    sizes = [int(x) for x in args.sizes.split(",")]
    for n in sizes:
        last = n == max(sizes)
        reps = args.repeats if n <= 200 else 1
        walls, res = [], None
        for _ in range(reps):
            w, res = _run(n, args.worst if last else None, args.out if last else None)
            walls.append(w)
        wall = statistics.median(walls)
        goal = 120 if n <= 200 else 600
        tests = {k[5:]: v for k, v in res.timings.items() if k.startswith("test ")}
        print(f"  {n:5d} units: {wall:7.1f} s (median of {reps}; goal < {goal} s; "
              f"{wall / n * 1000:.0f} ms per unit)  yield {100 * res.overall.value:.1f} % "
              f"[{100 * res.overall.interval[0]:.1f}, {100 * res.overall.interval[1]:.1f}]")
        steps, kernel_s = res.timings["kernel_lane_steps"], res.timings["kernel_s"]
        print(f"      kernel: {steps / 1e9:.2f} G lane-steps, {steps / kernel_s / 1e6:.1f} M "
              f"lane-steps/s inside the kernel, {steps / res.timings['yield_s'] / 1e6:.1f} M/s "
              f"of the run's wall ({100 * kernel_s / res.timings['yield_s']:.0f} % in the "
              "kernel)")
        for name, t in sorted(tests.items(), key=lambda kv: -kv[1]):
            print(f"      {name:22s} {t:7.1f} s  ({t / n * 1000:6.1f} ms per unit)")
        if last:
            print(f"  then the worst-case search (budget {args.worst} per test): "
                  f"{res.timings['worst_case_s']:.1f} s; units evaluated per test: "
                  f"{res.worst.evaluated}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

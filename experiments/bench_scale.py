"""`make bench`: `ema yield` on the executor's backends (issue 41): units per second of the
bundled battery (configs/acceptance.yaml over configs/tolerances.yaml) in 1 process, in 2
loky processes, with 2 numba threads in this process (the default) and on a 2-worker Dask
cluster started here (LocalCluster: 2 worker processes, one thread each); and the Dask
overhead per block.

Each backend runs a warm-up first (loky's workers and Dask's load the kernel once: their cold
start is printed apart), then ``--n`` units (no worst-case search: the units alone); every
backend's units are asserted bit-identical to the first's (the one thing asserted). Units per
second are ``--n`` over the run's wall, median of ``--repeats``.

The Dask overhead per block: ``--blocks`` blocks of ``--units`` units (the yield's smallest
task on a remote backend, ``production.run.TASK_UNITS``) sent one at a time; the overhead is
the parent's wall per block minus the seconds the block ran on its worker (submission,
serialisation both ways, scheduling, the result's transfer), median over the blocks, as a
share of the block's median seconds.

Read the rates with the machine's load: each row prints the 1-minute load average, and the
kernel-busy workers (the seconds spent in the kernel, summed over the workers, over the wall):
near 2 when both loky or Dask workers compute all the time (the threads backend is one process
whose kernel calls use both threads: at most 1). On 2 cores shared with other jobs, 2 busy
workers get no more CPU than 1, and the rate does not scale although the work is spread.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import pandas as pd

from ema_cli.api.production import _plan, production_yield
from ema_cli.production.run import TASK_UNITS, run_task
from ema_cli.sweep.executor import Task, executing

ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "configs" / "acceptance.yaml"
TOL = ROOT / "configs" / "tolerances.yaml"
BLOCK = 100  # the yield's default checkpoint block (api.production.DEFAULT_BLOCK) [units]


def run(n: int, **backend: object) -> tuple[float, pd.DataFrame, float]:
    """One yield of ``n`` units -> (wall [s], samples, seconds in the kernel summed over the
    workers [s])."""
    t0 = time.perf_counter()
    res = production_yield(SPEC, TOL, n=n, seed=0, block=BLOCK, worst_budget=None,
                           drivers=False, **backend)
    return time.perf_counter() - t0, res.samples, res.timings["kernel_s"]


def overhead(scheduler: str, blocks: int, units: int) -> tuple[float, float]:
    """Blocks of ``units`` units one at a time on the cluster -> (median overhead per block,
    median block seconds on its worker) [s]."""
    plan = _plan(str(SPEC), str(TOL), None, 0, "random", None)
    plan.rows = []
    over, inside = [], []
    with executing("dask", scheduler=scheduler) as ex:
        for b in range(blocks):
            start = 1000 + b * units
            task = Task(run_task, (plan, start, plan.values(start, start + units)),
                        f"units {start}-{start + units - 1}")
            t0 = time.perf_counter()
            ex.run([task])
            wall = time.perf_counter() - t0
            over.append(wall - ex.task_seconds[-1])
            inside.append(ex.task_seconds[-1])
    return statistics.median(over), statistics.median(inside)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=64, help="units per run")
    ap.add_argument("--repeats", type=int, default=1, help="runs per backend (median)")
    ap.add_argument("--blocks", type=int, default=5, help="blocks timed for the overhead")
    ap.add_argument("--units", type=int, default=TASK_UNITS, help="units per timed block")
    args = ap.parse_args()
    import distributed

    threads = os.environ.get("NUMBA_NUM_THREADS", "all")
    print(f"\n== ema yield on the backends: {SPEC.name} x {TOL.name}, {args.n} units, "
          f"checkpoint blocks of {BLOCK} (numba threads: {threads}; median of {args.repeats}; "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f})")
    rows, ref = [], None
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        setups = [("1 process", {"n_jobs": 1}),
                  ("2 processes (loky)", {"backend": "loky", "n_jobs": 2}),
                  ("2 threads, this process", {"backend": "threads", "n_jobs": 2}),
                  ("Dask, 2 workers", {"backend": "dask",
                                       "scheduler": cluster.scheduler_address})]
        for name, kw in setups:
            cold, _, _ = run(2 * TASK_UNITS if kw.get("backend") in ("loky", "dask") else 4,
                          **kw)
            walls, busy = [], []
            for _ in range(args.repeats):
                wall, samples, kernel_s = run(args.n, **kw)
                walls.append(wall)
                busy.append(kernel_s / wall)
                if ref is None:
                    ref = samples
                pd.testing.assert_frame_equal(samples, ref, check_exact=True)
            wall = statistics.median(walls)
            rows.append((name, wall, args.n / wall, cold))
            rate, base = rows[-1][2], rows[0][2]
            print(f"  {name:26s} {wall:7.1f} s  {rate:6.3f} units/s  x{rate / base:4.2f} vs 1 "
                  f"process  kernel-busy workers {statistics.median(busy):4.2f}  (warm-up "
                  f"{cold:5.1f} s; load average {os.getloadavg()[0]:.1f})", flush=True)
        over, block_s = overhead(cluster.scheduler_address, args.blocks, args.units)
    print(f"  every backend's {args.n} units: bit-identical to the first's")
    per_unit = block_s / args.units
    print(f"  Dask overhead per block: {1e3 * over:.1f} ms against a {args.units}-unit block of "
          f"{block_s:.2f} s: {100 * over / block_s:.2f} % (goal < 5 %); at the default "
          f"block of {BLOCK} units (~{BLOCK * per_unit:.0f} s): "
          f"{100 * over / (BLOCK * per_unit):.3f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

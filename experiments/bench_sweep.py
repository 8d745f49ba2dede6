"""Benchmark: 1,000-job sweeps (0.1 deg step, 1 s, dt 1e-5 s) end to end, metrics only and
with every signal recorded.

Runs ``run_sweep`` in a fresh process on a fresh cache and output folder each repeat (so every
job is computed and stored, the kernel is loaded and workers start) and prints medians over the
repeats.

1. Metrics only, for each local backend: the end-to-end wall time of ``run_sweep`` (plan ->
   cache lookup -> kernel load -> kernel -> cache writes -> metrics.csv/manifest/summary), the
   kernel time, and the runner's overhead (everything but the kernel) as a share of the kernel
   time. "rest" is the overhead not in a named part: worker start-up and dispatch, chunk
   assembly. Goals: wall < 2 s on a 2-core machine (kernel v2), overhead < 20 % of the kernel
   time (issue 3, set when the kernel was 3x slower; each goal gets its own verdict).
2. Recording on (``outputs.timeseries``), every 1e-4 s (10,001 samples x 17 signals per
   job, 1.36 GB of float64 in all) and every 1e-3 s, default backend: the output-writing time
   — streaming signals.parquet as chunks finish plus the closing outputs (metrics.csv,
   renaming the parquet file into place, summary, manifest) — as a share of the kernel time.
   Goal < 20 % (issue 9: a 401-job sweep once spent 85.7 s of 92.6 s writing per-job CSVs).
   The job cache stores the signals a second time (checksummed), alongside signals.parquet in
   another thread; "all writes" is the wall time the sweep spent on both, plus the closing
   outputs, and gets its own verdict against the same goal.

Usage: ``python experiments/bench_sweep.py [--repeats N] [--backends threads,loky]
[--intervals 1e-4,1e-3] [--no-recording]``; the function ``main()`` is what
``experiments/bench.py`` calls.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ema_cli.config.loader import validate
from ema_cli.config.study import StudyConfig
from ema_cli.report.sweep_report import run_sweep
from ema_cli.sim.tables import N_SIGNALS
from ema_cli.sweep.execute import cpu_count

N_JOBS = 1000  # jobs in the benchmark sweep, baseline included
REPEATS = 3  # repeats per backend; medians are reported
WALL_GOAL_S = 2.0  # end-to-end goal on 2 cores [s]
OVERHEAD_GOAL = 0.20  # overhead goal, fraction of the kernel time [-]
OUTPUT_GOAL = 0.20  # recording on: output-writing goal, fraction of the kernel time [-]
OUTPUT_INTERVALS_S = (1e-4, 1e-3)  # recording on: the signals' sample intervals [s]
BACKENDS = ("threads", "loky")
RECORDING_BACKEND = "threads"  # what `auto` picks on one machine


def bench_config(record: float | None = None) -> StudyConfig:
    """The benchmark study: deadzone2 over 999 log-spaced half-widths + the baseline;
    ``record``: every signal recorded at this interval [s] into signals.parquet."""
    return validate(StudyConfig, {
        "name": "bench-sweep",
        "input": {"kind": "step", "amplitude_deg": 0.1},
        "simulation": {"duration_s": 1.0, "dt_s": 1e-5, "output_interval_s": record or 1e-4},
        "sweep": {"axes": [{"nonlinearity": "deadzone2",
                            "logspace": {"start": 1e-4, "stop": 0.1, "num": N_JOBS - 1}}],
                  "baseline": True},
        "outputs": {"timeseries": record is not None, "figures": []},
    }, "bench")


def run_once(backend: str, workers: int, record: float | None = None) -> dict[str, float]:
    """One end-to-end sweep on a fresh cache and folder -> timings [s] (and sizes [bytes])."""
    cfg = bench_config(record)
    with tempfile.TemporaryDirectory(prefix="ema-bench-") as tmp:
        t0 = time.perf_counter()
        res = run_sweep(cfg, Path(tmp) / "out", n_jobs=workers, backend=backend,
                        progress=False, cache_dir=Path(tmp) / "cache")
        wall = time.perf_counter() - t0
        size = res.signals_file.stat().st_size if res.signals_file is not None else 0
    counts = res.counts()
    if counts["ok"] + counts["diverged"] != N_JOBS or res.computed != res.plan.n_unique:
        raise RuntimeError(f"benchmark sweep incomplete: {counts}, computed {res.computed}")
    t = res.timings
    parallel = 1 if res.backend in ("threads", "serial") else workers
    kernel = t["kernel"] / parallel  # kernel wall: summed chunk times / concurrent workers
    outputs = t.get("outputs", 0.0)
    named = t["plan"] + t["lookup"] + t["warm"] + t["writes"] + outputs
    return {"wall": wall, "kernel": kernel, "overhead": wall - kernel, "plan": t["plan"],
            "lookup": t["lookup"], "warm": t["warm"], "store": t["store"],
            "signals": t["signals"], "outputs": outputs, "writing": t["signals"] + outputs,
            "all_writes": t["writes"] + outputs, "rest": wall - kernel - named,
            "parquet_bytes": size}


def _run_fresh(backend: str, workers: int, record: float | None = None) -> dict[str, float]:
    """``run_once`` in a new Python process: nothing warm (kernel load, workers, imports)."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, __file__, "--one", backend, "--workers", str(workers)]
                          + (["--record", repr(record)] if record else []),
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark run failed:\n{proc.stderr}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["process"] = time.perf_counter() - t0
    return out


def main(repeats: int = REPEATS, backends: tuple[str, ...] = BACKENDS,
         intervals: tuple[float, ...] = OUTPUT_INTERVALS_S) -> dict[str, Any]:
    """Run the benchmark and print one line per backend, then two per recorded interval;
    returns the medians per backend and per interval (key ``recording <interval>``).

    Every repeat is a fresh process (kernel loaded from numba's cache, workers started, a new
    job cache), and the backends alternate so a busy neighbour slows them alike.
    """
    workers = cpu_count()
    load = os.getloadavg()[0]
    print(f"1,000-job sweep (0.1 deg step, 1 s, dt 1e-5 s, metrics only), {workers} cores, "
          f"median of {repeats} fresh processes (load average before: {load:.2f})")
    runs: dict[str, list[dict[str, float]]] = {b: [] for b in backends}
    for _ in range(repeats):
        for backend in backends:
            runs[backend].append(_run_fresh(backend, workers))
    out: dict[str, Any] = {}
    for backend in backends:
        med = {k: statistics.median(r[k] for r in runs[backend]) for k in runs[backend][0]}
        share = med["overhead"] / med["kernel"]
        out[backend] = {**med, "overhead_share": share}
        ok_wall = "OK" if med["wall"] < WALL_GOAL_S else "MISSED"
        ok_share = "OK" if share < OVERHEAD_GOAL else "MISSED"
        print(f"  {backend:8s} wall {med['wall']:5.2f} s  kernel {med['kernel']:5.2f} s  "
              f"overhead {med['overhead']:4.2f} s = {share:5.1%} of kernel "
              f"[plan {med['plan']:.2f}, lookup {med['lookup']:.2f}, kernel load "
              f"{med['warm']:.2f}, cache writes {med['store']:.2f}, outputs "
              f"{med['outputs']:.2f}, rest {med['rest']:.2f}]  (process incl. imports "
              f"{med['process']:.2f} s)  wall < {WALL_GOAL_S:g} s: {ok_wall}, overhead < "
              f"{OVERHEAD_GOAL:.0%}: {ok_share}")
    if len(out) > 1:
        best = min(out, key=lambda b: out[b]["wall"])
        print(f"  fastest local backend: {best} (load average after: {os.getloadavg()[0]:.2f})")
    for interval in intervals:
        out[f"recording {interval:g}"] = recording_bench(repeats, workers, interval)
    return out


def recording_bench(repeats: int, workers: int, interval: float) -> dict[str, float]:
    """The sweep recording every ``interval`` s, medians of ``repeats`` fresh runs."""
    n_out = round(1.0 / interval) + 1
    raw = N_JOBS * n_out * N_SIGNALS * 8
    print(f"1,000-job sweep recording every signal every {interval:g} s ({n_out:,} samples x "
          f"{N_SIGNALS} signals per job, {raw / 1e9:.2f} GB of float64), backend "
          f"{RECORDING_BACKEND}, median of {repeats} fresh processes (load average before: "
          f"{os.getloadavg()[0]:.2f})")
    runs = [_run_fresh(RECORDING_BACKEND, workers, interval) for _ in range(repeats)]
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    share, all_share = med["writing"] / med["kernel"], med["all_writes"] / med["kernel"]
    med.update(writing_share=share, all_writes_share=all_share)

    def verdict(x: float) -> str:
        return "OK" if x < OUTPUT_GOAL else "MISSED"

    print(f"  wall {med['wall']:5.2f} s  kernel {med['kernel']:5.2f} s  output writing "
          f"{med['writing']:4.2f} s = {share:5.1%} of kernel [signals.parquet streamed "
          f"{med['signals']:.2f}, closing outputs {med['outputs']:.2f}; "
          f"{med['parquet_bytes'] / 1e6:.0f} MB on disk, {raw / med['writing'] / 1e9:.2f} GB/s "
          f"of signals]  < {OUTPUT_GOAL:.0%}: {verdict(share)}")
    print(f"  {'':28s}all writes {med['all_writes']:4.2f} s = {all_share:5.1%} of kernel "
          f"[job cache {med['store']:.2f} s alongside signals.parquet]  < {OUTPUT_GOAL:.0%}: "
          f"{verdict(all_share)}")
    return med


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--backends", default=",".join(BACKENDS))
    ap.add_argument("--one", help=argparse.SUPPRESS)
    ap.add_argument("--intervals", default=",".join(f"{x:g}" for x in OUTPUT_INTERVALS_S),
                    help="recorded sweeps: their output intervals [s]")
    ap.add_argument("--no-recording", action="store_true",
                    help="skip the sweeps with every signal recorded")
    ap.add_argument("--workers", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--record", type=float, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        print(json.dumps(run_once(a.one, a.workers or cpu_count(), a.record)))
    else:
        intervals = () if a.no_recording else tuple(
            float(x) for x in a.intervals.split(",") if x)
        main(a.repeats, tuple(b for b in a.backends.split(",") if b), intervals)

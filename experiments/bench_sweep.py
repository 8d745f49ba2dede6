"""Benchmark: a 1,000-job sweep (0.1 deg step, 1 s, dt 1e-5 s, metrics only), end to end.

Runs ``run_sweep`` in a fresh process on a fresh cache and output folder each repeat (so every
job is computed and stored, the kernel is loaded and workers start), for each local backend,
and prints medians over the repeats of: the end-to-end wall time of ``run_sweep`` (plan ->
cache lookup -> kernel load -> kernel -> cache writes -> metrics.csv/manifest/summary), the
kernel time, and the runner's overhead (everything but the kernel) as a share of the kernel
time. "rest" is the overhead not in a named part: worker start-up and dispatch, chunk
assembly. Goals: wall < 2 s on a 2-core machine (kernel v2), overhead < 20 % of the kernel time
(issue 3, set when the kernel was 3x slower; each goal gets its own verdict).

Usage: ``python experiments/bench_sweep.py [--repeats N] [--backends threads,loky]``; the
function ``main()`` is what ``experiments/bench.py`` calls.
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
from ema_cli.config.schema import StudyConfig
from ema_cli.report.sweep_report import run_sweep
from ema_cli.sweep.execute import cpu_count

N_JOBS = 1000  # jobs in the benchmark sweep, baseline included
REPEATS = 3  # repeats per backend; medians are reported
WALL_GOAL_S = 2.0  # end-to-end goal on 2 cores [s]
OVERHEAD_GOAL = 0.20  # overhead goal, fraction of the kernel time [-]
BACKENDS = ("threads", "loky")


def bench_config() -> StudyConfig:
    """The benchmark study: deadzone2 over 999 log-spaced half-widths + the baseline."""
    return validate(StudyConfig, {
        "name": "bench-sweep",
        "input": {"kind": "step", "amplitude_deg": 0.1},
        "simulation": {"duration_s": 1.0, "dt_s": 1e-5, "output_interval_s": 1e-4},
        "sweep": {"axes": [{"nonlinearity": "deadzone2",
                            "logspace": {"start": 1e-4, "stop": 0.1, "num": N_JOBS - 1}}],
                  "baseline": True},
        "outputs": {"timeseries": False, "figures": []},
    }, "bench")


def run_once(backend: str, workers: int) -> dict[str, float]:
    """One end-to-end sweep on a fresh cache and folder -> timings [s]."""
    cfg = bench_config()
    with tempfile.TemporaryDirectory(prefix="ema-bench-") as tmp:
        t0 = time.perf_counter()
        res = run_sweep(cfg, Path(tmp) / "out", n_jobs=workers, backend=backend,
                        progress=False, cache_dir=Path(tmp) / "cache")
        wall = time.perf_counter() - t0
    counts = res.counts()
    if counts["ok"] + counts["diverged"] != N_JOBS or res.computed != res.plan.n_unique:
        raise RuntimeError(f"benchmark sweep incomplete: {counts}, computed {res.computed}")
    t = res.timings
    parallel = 1 if res.backend in ("threads", "serial") else workers
    kernel = t["kernel"] / parallel  # kernel wall: summed chunk times / concurrent workers
    named = t["plan"] + t["lookup"] + t["warm"] + t["store"] + t.get("outputs", 0.0)
    return {"wall": wall, "kernel": kernel, "overhead": wall - kernel, "plan": t["plan"],
            "lookup": t["lookup"], "warm": t["warm"], "store": t["store"],
            "outputs": t.get("outputs", 0.0), "rest": wall - kernel - named}


def _run_fresh(backend: str, workers: int) -> dict[str, float]:
    """``run_once`` in a new Python process: nothing warm (kernel load, workers, imports)."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, __file__, "--one", backend, "--workers", str(workers)],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark run failed:\n{proc.stderr}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["process"] = time.perf_counter() - t0
    return out


def main(repeats: int = REPEATS, backends: tuple[str, ...] = BACKENDS) -> dict[str, Any]:
    """Run the benchmark and print one line per backend; returns the medians per backend.

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
    return out


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--backends", default=",".join(BACKENDS))
    ap.add_argument("--one", help=argparse.SUPPRESS)
    ap.add_argument("--workers", type=int, default=0, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.one:
        print(json.dumps(run_once(a.one, a.workers or cpu_count())))
    else:
        main(a.repeats, tuple(b for b in a.backends.split(",") if b))

"""Benchmark: what a newcomer waits for the compiler (issue 20's goals on 2 idle cores: every
kernel from scratch < 20 s, a cold ``ema simulate`` < 15 s as a whole process).

Medians over repeats, each in a fresh, empty compiled-code cache (``EMA_CACHE_DIR``):

- ``ema compile``: every unit (``sim.compiled.units``: each entry point in each variant, and
  the identification kernels), in two processes, as ``make run`` does it;
- a cold ``ema simulate`` (empty cache: it compiles the one unit it needs);
- a warm ``ema simulate`` (the same, its unit cached);

wall time and CPU time (user + system of the process and its children: what a loaded machine
stretches less).

Usage: ``python experiments/bench_compile.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPEATS = 3
GOALS = {"ema compile (every unit, cold)": 20.0, "ema simulate (cold cache)": 15.0,
         "ema simulate (warm cache)": 1.5}


def _timed(args: list[str], cache: Path, out: Path | None = None) -> tuple[float, float]:
    """One whole ``ema`` process -> (wall [s], CPU of it and its children [s])."""
    env = {**os.environ, "EMA_CACHE_DIR": str(cache), "COLUMNS": "100"}
    env.pop("NUMBA_DISABLE_JIT", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    cmd = [sys.executable, "-c", "from ema_cli.cli.main import main; main()", *args]
    if out is not None:
        cmd += ["--out", str(out)]
    subprocess.run(cmd, cwd=ROOT, env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def measure(repeats: int = REPEATS) -> dict[str, tuple[float, float]]:
    """Median (wall, CPU) [s] of each case."""
    res: dict[str, list[tuple[float, float]]] = {k: [] for k in GOALS}
    with tempfile.TemporaryDirectory(prefix="ema-bench-compile-") as tmp:
        for i in range(repeats):
            res["ema compile (every unit, cold)"].append(
                _timed(["compile"], Path(tmp) / f"c{i}"))
            cache = Path(tmp) / f"s{i}"
            res["ema simulate (cold cache)"].append(
                _timed(["simulate"], cache, Path(tmp) / f"sim{i}a"))
            res["ema simulate (warm cache)"].append(
                _timed(["simulate"], cache, Path(tmp) / f"sim{i}b"))
    return {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v))
            for k, v in res.items()}


def main(repeats: int = REPEATS) -> bool:
    """Print the medians against the goals; True when every goal is met."""
    ok = True
    print(f"compile and start-up, medians of {repeats} (each in a fresh cache), "
          f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}")
    for name, (wall, cpu) in measure(repeats).items():
        goal = GOALS[name]
        met = wall < goal
        ok &= met
        print(f"  {name:34s} wall {wall:6.1f} s  cpu {cpu:6.1f} s   goal < {goal:g} s: "
              f"{'met' if met else 'NOT met'}")
    return ok


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=REPEATS)
    sys.exit(0 if main(ap.parse_args().repeats) else 1)

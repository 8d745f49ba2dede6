"""Benchmark: whole `ema` processes, as a user starts them (issue 9's start-up goals).

Times, as medians over repeats of fresh processes on this machine:

- ``ema --help``                                  goal < 0.5 s
- ``ema validate configs/deadzone2.yaml``         goal < 1.0 s
- ``ema simulate`` (the 1 s default run, compiled kernel already cached, every output written)
                                                  goal < 1.5 s

and the breakdown of ``ema simulate`` from its manifest (``timings_s``): imports (numpy, numba,
the config schema; matplotlib is imported meanwhile by the forked figure worker,
``report/figure_worker.py``), config, kernel load (numba cache), simulation (the kernel alone),
CSV, figure (drawn and written by the worker while the CSVs are written); "rest" is interpreter
start-up, typer and what is not in a named part. The kernel cache is warmed by one untimed run
first (the goal is for a cached kernel; a first run after an edit of the model compiles).

Usage: ``python experiments/bench_startup.py [--repeats N]``; ``main()`` is what
``experiments/bench.py`` calls.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EMA = Path(sys.executable).with_name("ema")
REPEATS = 7
GOALS = {"ema --help": 0.5, "ema validate configs/deadzone2.yaml": 1.0, "ema simulate": 1.5}
PARTS = ("imports", "config", "kernel_load", "simulation", "csv", "figure")


def _run(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([str(EMA), *args], cwd=ROOT, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL, env={**os.environ, "COLUMNS": "100"})
    return time.perf_counter() - t0


def measure(repeats: int = REPEATS) -> dict[str, object]:
    """Median wall times [s] of the three commands and the simulate breakdown."""
    walls: dict[str, list[float]] = {k: [] for k in GOALS}
    parts: dict[str, list[float]] = {k: [] for k in (*PARTS, "rest")}
    with tempfile.TemporaryDirectory(prefix="ema-bench-startup-") as tmp:
        _run(["simulate", "--out", f"{tmp}/warm"])  # the kernel cache is warm from here on
        for i in range(repeats):
            walls["ema --help"].append(_run(["--help"]))
            walls["ema validate configs/deadzone2.yaml"].append(
                _run(["validate", "configs/deadzone2.yaml"]))
            out = Path(tmp) / f"run{i}"
            wall = _run(["simulate", "--out", str(out)])
            walls["ema simulate"].append(wall)
            t = json.loads((out / "manifest.json").read_text())["timings_s"]
            named = 0.0
            for k in PARTS:
                parts[k].append(t.get(k, 0.0))
                named += t.get(k, 0.0)
            parts["rest"].append(wall - named)
            shutil.rmtree(out)
    return {"walls": {k: statistics.median(v) for k, v in walls.items()},
            "parts": {k: statistics.median(v) for k, v in parts.items()},
            "repeats": repeats}


def main(repeats: int = REPEATS) -> bool:
    """Print the table and the verdicts; True if every goal is met."""
    res = measure(repeats)
    print(f"\n## Start-up: whole processes (median of {res['repeats']}, kernel cache warm)\n")
    print("| command | wall [s] | goal [s] | verdict |")
    print("|---|---:|---:|---|")
    ok = True
    for cmd, goal in GOALS.items():
        w = res["walls"][cmd]
        met = w < goal
        ok &= met
        print(f"| `{cmd}` | {w:.2f} | < {goal:g} | {'met' if met else 'NOT met'} |")
    print("\n`ema simulate` breakdown (medians, from its manifest):\n")
    print("| part | time [ms] |")
    print("|---|---:|")
    for k, v in res["parts"].items():
        print(f"| {k.replace('_', ' ')} | {v * 1e3:.0f} |")
    return ok


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=REPEATS)
    main(ap.parse_args().repeats)

"""Benchmark: the developer loop, `make test` as a developer runs it (issue 20's goal: the
whole default suite under 120 s on 2 idle cores).

Times, as medians over repeats of whole ``pytest`` processes with the options ``make test``
uses (the compiled kernels already cached: ``make test`` compiles them first with
``ema compile``), the wall time of the default tier, and once the ten slowest tests
(``--durations``). Run on an idle machine; the figure is only as good as the machine's quiet.

Usage: ``python experiments/bench_tests.py [--repeats N] [--all]`` (``--all``: the slow tier
too, as ``make test-all``).
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOAL_S = 120.0  # the default tier on 2 idle cores [s]
REPEATS = 3


def pytest_args(everything: bool) -> list[str]:
    """The pytest command ``make test`` (or ``make test-all``) runs."""
    marks = [] if everything else ["-m", "not slow"]
    return [sys.executable, "-m", "pytest", "-n", "auto", "-p", "no:cacheprovider", *marks]


def run_once(everything: bool, durations: bool = False) -> tuple[float, str]:
    """One whole pytest process -> (wall time [s], its output)."""
    args = pytest_args(everything) + (["--durations=10"] if durations else [])
    t0 = time.perf_counter()
    out = subprocess.run(args, cwd=ROOT, capture_output=True, text=True,
                         env={**os.environ, "COLUMNS": "100"})
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"pytest failed (exit {out.returncode}):\n{out.stdout[-3000:]}")
    return wall, out.stdout


def main(repeats: int = REPEATS, everything: bool = False) -> bool:
    """Print the medians; True when the default tier meets its goal."""
    walls = []
    summary = ""
    for i in range(repeats):
        wall, text = run_once(everything, durations=(i == 0))
        walls.append(wall)
        if i == 0:
            slow = [ln for ln in text.splitlines() if re.match(r"^\s*[0-9.]+s (call|setup)", ln)]
            summary = "\n".join(slow[:10])
            counts = [ln for ln in text.splitlines() if re.search(r"\d+ passed", ln)]
            print(counts[-1].strip("= ") if counts else "")
    med = statistics.median(walls)
    tier = "make test-all" if everything else "make test"
    runs = ", ".join(f"{w:.1f}" for w in walls)
    verdict = "met" if med < GOAL_S else "NOT met"
    goal = "" if everything else f"; goal < {GOAL_S:.0f} s: {verdict}"
    print(f"{tier}: median {med:.1f} s over {repeats} runs ({runs}){goal}")
    print("slowest tests (first run):\n" + summary)
    return everything or med < GOAL_S


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--all", action="store_true", help="the slow tier too (make test-all)")
    a = ap.parse_args()
    sys.exit(0 if main(a.repeats, a.all) else 1)

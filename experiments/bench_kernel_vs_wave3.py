"""`make bench`: the kernel's throughput on the paper's EMA against the wave-3 kernel (before
actuator descriptions), both measured in this one run.

The wave-3 package is materialised from git (commit ``WAVE3``) into a temporary folder with its
own compiled-code cache; each side runs in a process of its own, alternately (old, new, old,
new, ...), and the medians of the repeats are compared. Cases: the default actuator, backlash,
LuGre friction and the digital controller, one configuration (the one-lane path) and 256 on
every core (SIMD lanes), 1e5 steps of 1e-5 s, metrics only.

    python experiments/bench_kernel_vs_wave3.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WAVE3 = "80f883b"  # the last commit of the third wave (the kernel with positional tuples)
CASES = {"defaults": {}, "backlash 0.01 deg": {"alpha": 0.01 * 3.141592653589793 / 180},
         "LuGre friction": {"friction": 1, "sigma2": 0.01}, "digital controller": {"Ts": 1e-3}}
BATCHES = ((1, False), (256, True))
STEPS = 100_000

PROBE = """
import json, sys, time, statistics
import numpy as np
from ema_cli.model.params import resolve, to_row
from ema_cli.sim.runner import simulate_batch
from ema_cli.sim.signals import InputSignal
cases = json.loads(sys.argv[1]); batches = json.loads(sys.argv[2]); n = int(sys.argv[3])
sig = InputSignal(amplitude=0.1 * 3.141592653589793 / 180)
out = {}
for name, over in cases.items():
    row = to_row(resolve(over))
    for batch, par in batches:
        P = np.array([row] * batch)
        simulate_batch(P, [sig], None, 1e-5, 1000, 0, parallel=par)  # loaded
        t0 = time.perf_counter()
        simulate_batch(P, [sig], None, 1e-5, n, 0, parallel=par)
        out[f"{name} x{batch}"] = batch * n / (time.perf_counter() - t0)
print(json.dumps(out))
"""


def _materialise(commit: str, dest: Path) -> None:
    archive = subprocess.run(["git", "archive", commit, "ema_cli"], cwd=ROOT, check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)


def _probe(pythonpath: Path, cache: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(pythonpath), EMA_CACHE_DIR=str(cache))
    r = subprocess.run([sys.executable, "-c", PROBE, json.dumps(CASES),
                        json.dumps(BATCHES), str(STEPS)], env=env, capture_output=True,
                       text=True, check=True, cwd=pythonpath)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="ema-wave3-") as tmp:
        old_root = Path(tmp) / "wave3"
        old_root.mkdir()
        _materialise(WAVE3, old_root)
        caches = {"old": Path(tmp) / "cache-old", "new": Path(tmp) / "cache-new"}
        roots = {"old": old_root, "new": ROOT}
        runs: dict[str, list[dict[str, float]]] = {"old": [], "new": []}
        for side in ("old", "new"):  # compile (not timed)
            _probe(roots[side], caches[side])
        for _ in range(a.repeats):
            for side in ("old", "new"):
                runs[side].append(_probe(roots[side], caches[side]))
    print(f"kernel throughput on the paper's EMA, M system-steps/s (median of {a.repeats}, "
          "alternating processes)")
    print(f"{'case':32s} {'wave 3':>10s} {'now':>10s} {'ratio':>7s}")
    ratios = []
    for key in runs["old"][0]:
        old = statistics.median(r[key] for r in runs["old"]) / 1e6
        new = statistics.median(r[key] for r in runs["new"]) / 1e6
        ratios.append(new / old)
        print(f"{key:32s} {old:10.2f} {new:10.2f} {new / old:7.3f}")
    print(f"{'median ratio':32s} {'':>10s} {'':>10s} {statistics.median(ratios):7.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

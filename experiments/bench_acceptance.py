"""`make bench`: the frequency response (30 frequencies x 3 amplitudes, `ema freqresp`'s
defaults) and the whole acceptance battery of configs/acceptance.yaml, in process (warm kernel),
and `ema acceptance` as a whole process once.

Medians of REPEATS runs after one warm-up, measured in this one run; nothing is asserted.
Issue 10's goals: the sinestream under 10 s, the battery under 30 s on 2 cores.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ema_cli.api import acceptance, freqresp

REPEATS = 3
ROOT = Path(__file__).resolve().parent.parent
SPEC = ROOT / "configs" / "acceptance.yaml"


def _median(fn, repeats: int = REPEATS) -> tuple[float, object]:
    out = fn()
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls), out


def main() -> int:
    threads = os.environ.get("NUMBA_NUM_THREADS", "all")
    print(f"\n== frequency response and acceptance (numba threads: {threads}; medians of "
          f"{REPEATS} after a warm-up)")
    t_fr, fr = _median(lambda: freqresp())
    print(f"  sinestream 30 frequencies x 3 amplitudes (0.5-50 Hz): {t_fr:6.2f} s   "
          f"(goal < 10 s; {len(fr.points)} simulations)")
    t_acc, res = _median(lambda: acceptance(SPEC))
    print(f"  acceptance battery, {len(res.runs)} tests:                {t_acc:6.2f} s   "
          f"(goal < 30 s; {'PASS' if res.passed else 'FAIL'})")
    for r in res.runs:
        print(f"    {r.name:22s} {r.kind:20s} {r.wall_s:6.2f} s")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([str(Path(sys.executable).with_name("ema")), "acceptance", str(SPEC),
                        "--out", str(Path(tmp) / "acc")], check=True, capture_output=True)
        wall = time.perf_counter() - t0
    print(f"  `ema acceptance configs/acceptance.yaml` as a process (start-up, figures, "
          f"files): {wall:.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

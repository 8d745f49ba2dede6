"""`make bench`: `ema duty` on the bundled 8.6 h TVC endurance profile (configs/duty/tvc.yaml),
in process (warm kernels) with and without the hot actuator's check, and as a whole process;
then the same profile with every cycle count divided by 100 against its full-resolution
simulation (the mechanics and the thermal network at the mechanical step).

Medians of REPEATS runs after one warm-up, measured in this one run; nothing is asserted.
Issue 40's goals: the 8.6 h profile under 10 s on 2 cores; on the /100 profile the multirate
peak winding temperature within 0.5 K of full resolution (tests/system/test_duty_reference.py
asserts it); the brute-force time is printed.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ema_cli.api.duty import duty

REPEATS = 3
ROOT = Path(__file__).resolve().parent.parent
TVC = ROOT / "configs" / "duty" / "tvc.yaml"
CYCLES = (3700, 4800, 5000, 7000, 8500, 1500)


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
    print(f"\n== ema duty (numba threads: {threads}; medians of {REPEATS} after a warm-up)")
    t_cold, res = _median(lambda: duty(TVC, hot=False))
    th = res.run.thermal
    print(f"  TVC profile {res.expanded.duration / 3600:.2f} h, without the hot check: "
          f"{t_cold:6.2f} s   (goal < 10 s; mechanics {res.run.timings['mechanics_s']:.2f} s, "
          f"thermal {res.run.timings['thermal_s']:.2f} s; peak winding "
          f"{th.peak_w - 273.15:.2f} degC, {res.verdict})")
    t_hot, res = _median(lambda: duty(TVC, hot=True))
    print(f"  TVC profile with the hot check (freqresp and no-load rate, cold and hot):  "
          f"{t_hot:6.2f} s")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([str(Path(sys.executable).with_name("ema")), "duty", str(TVC),
                        "--out", str(Path(tmp) / "duty")], check=True, capture_output=True)
        wall = time.perf_counter() - t0
    print(f"  `ema duty configs/duty/tvc.yaml` as a process (start-up, hot check, figures, "
          f"files): {wall:.2f} s")
    over = {f"segments.{k}.sine.cycles": c // 100 for k, c in enumerate(CYCLES)}
    duty(TVC, overrides={"segments.0.sine.cycles": 2}, full_resolution=True, hot=False)  # warm
    t0 = time.perf_counter()
    small = duty(TVC, overrides=over, full_resolution=True, hot=False)
    wall = time.perf_counter() - t0
    ref = small.reference
    assert ref is not None
    t_multi = small.run.timings["mechanics_s"] + small.run.timings["thermal_s"]
    print(f"  /100 profile ({small.expanded.duration:.0f} s): multirate peak "
          f"{small.run.thermal.peak_w - 273.15:.3f} degC in {t_multi:.2f} s, full resolution "
          f"{ref.peak_w - 273.15:.3f} degC in {ref.wall_s:.1f} s ({ref.steps:,} steps); "
          f"difference {small.run.thermal.peak_w - ref.peak_w:+.4f} K (goal within 0.5 K); "
          f"whole call {wall:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""The EMPS axis from its documentation alone: the closed-loop simulation of the benchmark's
estimation record (configs/emps.yaml: the published IDIM-LS parameters, the Simulink model's
controller) scored as the benchmark scores it, with and without the Simulink model's one-sample
delay of the command, and its speed (median of repeats, warm).

    python -m experiments.emps_simulation            # the table
    python -m experiments.emps_simulation --repeats 5

Published (Janot, Gautier, Brunot 2019), on this record: position 0.013752 %, velocity
0.22911 %, acceleration 8.6036 %, force 5.848 %.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from ema_cli.api import simulate
from ema_cli.identify.plant.benchmark import (
    EMPS_SIMULATION_PUBLISHED_PCT,
    BenchmarkErrors,
    benchmark_errors,
)
from ema_cli.identify.plant.records import read_plant_mat

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "emps.yaml"
RECORD = ROOT / "experiments" / "data" / "emps" / "DATA_EMPS.mat"


def emps_errors(delay: int) -> tuple[BenchmarkErrors, float]:
    """The benchmark's four relative errors [%] of the simulation with a command delay of
    ``delay`` samples, and the run's kernel time [s]."""
    run = simulate(CONFIG, {"actuator.controller.delay_samples": delay})
    rec = read_plant_mat(RECORD)
    n = rec.n
    q = run.signal("x_load_mm")[:n] * 1e-3
    v = run.signal("v_load_mm_s")[:n] * 1e-3
    f = run.signal("drive_force_n")[:n]
    m = run.params["JL"]
    # the model's acceleration at each sample, the command applied from that sample on
    a = (f - run.signal("friction_load_n")[:n] + run.signal("force_load_n")[:n]) / m
    return benchmark_errors(rec, q, v, a, f), run.batch.kernel_s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    pub = EMPS_SIMULATION_PUBLISHED_PCT
    print(f"{'':28s} {'position':>10s} {'velocity':>10s} {'accel.':>10s} {'force':>10s}")
    print(f"{'published (Simulink, 1 late)':28s} " + " ".join(
        f"{pub[k]:9.4f}%" for k in ("position", "velocity", "acceleration", "force")))
    for delay in (1, 0):
        times = []
        for _ in range(max(args.repeats, 1)):
            t0 = time.perf_counter()
            err, _ = emps_errors(delay)
            times.append(time.perf_counter() - t0)
        d = err.as_dict()
        label = f"ema, command {'1 sample late' if delay else 'same sample'}"
        print(f"{label:28s} " + " ".join(f"{d[k]:9.4f}%" for k in
                                         ("position", "velocity", "acceleration", "force"))
              + f"   {statistics.median(times):.2f} s per run (median of {len(times)}, "
                "config to scores)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

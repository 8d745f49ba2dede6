"""Coverage of `ema identify plant`'s 95 % intervals: synthetic closed-loop records of the EMPS
description (tests/helpers/plant_records.py: the kernel driven by the first seconds of the EMPS
reference, white noise as a force disturbance, the encoder's quantiser) with stated truths, one
per seed; how often each parameter's interval holds its truth.

    python -m experiments.plant_coverage [--seeds 20] [--seconds 6] [--noise 0.07]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRUTH = {"M": 90.0, "Fv+": 200.0, "Fc+": 20.0, "Fv-": 200.0, "Fc-": 20.0, "OF": -3.0}
SYMMETRIC = {"M": 90.0, "Fv": 200.0, "Fc": 20.0, "OF": -3.0}


def main(argv: list[str] | None = None) -> int:
    sys.path.insert(0, str(ROOT))
    from ema_cli.identify.plant.fit import run_plant
    from ema_cli.identify.plant.settings import PlantSettings
    from tests.helpers.plant_records import ACTUATOR, make_record

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--noise", type=float, default=0.07, help="disturbance std [V]")
    args = ap.parse_args(argv)
    hits = dict.fromkeys(SYMMETRIC, 0)
    det = 0
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            p = make_record(Path(tmp) / f"r{seed}.mat", TRUTH, args.seconds, args.noise, seed)
            fit = run_plant(PlantSettings(data=str(p), actuator=str(ACTUATOR),
                                          law="symmetric", split=0.0))
            u = fit.best.uncertainty
            det += fit.best.determined()[0]
            row = []
            for j, n in enumerate(u.names):
                ok = u.ci_low[j] <= SYMMETRIC[n] <= u.ci_high[j]
                hits[n] += ok
                row.append(f"{n} {u.x[j]:.5g} [{u.ci_low[j]:.5g}, {u.ci_high[j]:.5g}]"
                           f"{'' if ok else ' MISS'}")
            print(f"seed {seed:2d}: " + "; ".join(row), flush=True)
    n = args.seeds
    print(f"coverage of the 95 % intervals over {n} records ({args.seconds:g} s, noise "
          f"{args.noise:g} V): " + ", ".join(f"{k} {v}/{n}" for k, v in hits.items())
          + f"; determined {det}/{n}; {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

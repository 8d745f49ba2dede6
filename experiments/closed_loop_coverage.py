"""Coverage of the closed-loop fit's 95 % intervals over noise seeds on a short log.

Each seed: a 1 s synthetic closed-loop log (1 % noise; truths away from the defaults, as the
short fit of tests/unit/test_shooting.py), the contact law stated (the data's), 4 starts,
segments lengthened to 0.1 and 0.2 s. Counts, over the four primary parameters, the intervals
that contain the truth, the confirmed optima and the adequate models; one line per seed as it
finishes (so an interrupted run still reports), then the totals.

    .venv/bin/python experiments/closed_loop_coverage.py --seeds 10
"""

from __future__ import annotations

import argparse
import json
import time

from ema_cli.identify.closed_loop.ga_fit import run_closed_loop
from ema_cli.identify.closed_loop.problem import CHANNELS, ClosedLoopLog
from ema_cli.identify.log_settings import ClosedLoopSettings
from ema_cli.identify.make_data import closed_loop_log
from ema_cli.units import DEG

PLANT = {"kL": 420.0, "alpha": 0.0055, "Fc": 0.05, "sigma2": 0.02}


def one(seed: int, duration: float) -> dict:
    """One seed's fit -> its coverage, verdicts and time."""
    syn = closed_loop_log(PLANT, 1.0, seed, duration_s=duration)
    c = syn.columns
    log = ClosedLoopLog(c["t_s"], c["theta_ref_deg"] * DEG,
                        {k: c[k] * CHANNELS[k][1] for k in CHANNELS}, f"seed {seed}", 0.0,
                        syn.truth)
    settings = ClosedLoopSettings(shooting={"starts": 4, "lengthen_s": [0.1, 0.2]},
                                  free_contact=False, profile_points=5, seed=seed)
    t0 = time.perf_counter()
    js = run_closed_loop(settings, log).to_json()
    return {"seed": seed, "covered": js["truth_in_ci95"], "error_pct": js["error_pct_vs_truth"],
            "confirmed": js["optimum"]["confirmed"],
            "adequate": (js.get("adequacy") or {}).get("adequate"),
            "failures": (js.get("adequacy") or {}).get("failures"),
            "s": time.perf_counter() - t0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--duration", type=float, default=1.0)
    a = ap.parse_args()
    rows = []
    for seed in range(a.seeds):
        r = one(seed, a.duration)
        rows.append(r)
        print(json.dumps(r), flush=True)
    n = sum(len(r["covered"]) for r in rows)
    k = sum(sum(r["covered"].values()) for r in rows)
    conf = sum(r["confirmed"] for r in rows)
    ok = sum(bool(r["adequate"]) for r in rows)
    print(f"intervals containing the truth: {k} of {n}; confirmed {conf} of {len(rows)}; "
          f"adequate {ok} of {len(rows)}")


if __name__ == "__main__":
    main()

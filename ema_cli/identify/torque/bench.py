"""Identification timings for `make bench`: a GA run at the paper's budget, the exact solver.

Nothing is asserted; :func:`bench_identify` returns the median wall times and prints them.
Budget targets from the issue: one GA run at 20,000 evaluations on ~4,000 samples < 0.5 s,
the exact solver < 50 ms.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ema_cli.identify.torque.exact import solve_exact
from ema_cli.identify.torque.run import build_problem, load_data, run_identification
from ema_cli.identify.torque.settings import IdentifySettings
from ema_cli.optim.ga import preset, run_ga
from ema_cli.timing import median_time

REPEATS = 5  # timed repeats after one warm-up call [-]
GA_TARGET_S = 0.5  # the target for one GA run at the paper's budget [s]
EXACT_TARGET_S = 0.05  # the target for the exact solver [s]


def bench_identify(log: Callable[[str], None] = print) -> dict[str, float]:
    """Measure and print the identification timings -> {name: seconds}."""
    settings = IdentifySettings()
    data = load_data(settings)
    out: dict[str, float] = {}
    log(f"\n== identification: {data.n_samples:,} samples (docs/model.md §8 chirp), "
        f"median of {REPEATS}")
    for form in ("contact", "paper"):
        prob = build_problem(settings.model_copy(update={"model": form}), data)
        for mode in ("paper", "improved"):
            opts = preset(mode)
            t = median_time(lambda p=prob, o=opts: run_ga(p, o, np.random.default_rng(0)))
            out[f"ga_{mode}_{form}_s"] = t
            log(f"  GA {mode:8s} mode, {form:7s} model, {opts.budget:,} evaluations: "
                f"{t * 1e3:7.1f} ms  ({opts.budget * data.n_samples / t / 1e6:.0f} M "
                f"sample-evaluations/s; target < {GA_TARGET_S * 1e3:.0f} ms)")
        for fit_c in (False, True):
            p = build_problem(settings.model_copy(update={"model": form, "fit_c": fit_c}), data)
            t = median_time(lambda p=p: solve_exact(p))
            key = f"exact_{form}{'_fit_c' if fit_c else ''}_s"
            out[key] = t
            log(f"  exact solver, {form:7s} model, c {'fitted' if fit_c else 'fixed '}:"
                f"          {t * 1e3:7.1f} ms  (target < {EXACT_TARGET_S * 1e3:.0f} ms)")
    t = median_time(lambda: run_identification(settings, data), 3)
    out["run_identification_s"] = t
    log(f"  run_identification (checks + exact + one improved GA run):   {t * 1e3:7.1f} ms")
    return out


if __name__ == "__main__":
    bench_identify()

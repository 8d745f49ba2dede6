"""Issue 23, exactness: where the yield has a closed form, the reported interval covers it as
often as it claims and the point estimate is unbiased.

The closed form: the current limit ``sat3`` ~ normal(30 A, 2 A) and a 20 deg step, whose peak
current is the current limit itself (the demand peaks at ~56 A, so the limit always clamps it;
checked to 0 A below). Limit: peak current <= 31 A, so the yield is P(sat3 <= 31 A) =
Phi((31 - 30) / 2) = 0.6915 exactly. 100 seeds x 500 units (slow tier); 10 seeds in the fast
tier."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from ema_cli.api.production import production_yield

SPEC = {"name": "current-limit", "actuator": {"config": None, "plant": {},
                                               "nonlinearities": {}},
        "tests": {"step": {"test": "step", "amplitude_deg": 20, "duration_s": 0.3,
                           "limits": {"peak_current": {"max": 31, "unit": "A"}}}}}
TOL = {"tolerances": {"plant.sat3": {"dist": "normal", "mean": 30, "sd": 2}}}
EXACT = float(norm.cdf((31 - 30) / 2))
N = 500


def _runs(seeds):
    out = []
    for seed in seeds:
        res = production_yield(SPEC, TOL, n=N, seed=seed, block=N, worst_budget=None,
                               drivers=False)
        s = res.samples
        # the measured quantity is the toleranced one, exactly
        assert np.array_equal(s["step/peak_current [A]"].to_numpy(), s["plant.sat3"].to_numpy())
        assert res.overall.n_inconclusive == 0
        lo, hi = res.overall.interval
        out.append((res.overall.value, lo <= EXACT <= hi))
    return out


def test_the_interval_covers_the_closed_form_yield_on_ten_seeds():
    runs = _runs(range(10))
    assert sum(c for _, c in runs) >= 9
    # the mean of 10 estimates: sd sqrt(p (1 - p) / 5000) = 0.0065
    assert abs(np.mean([v for v, _ in runs]) - EXACT) < 4 * 0.0065


@pytest.mark.slow
def test_the_interval_covers_the_closed_form_yield_in_95_of_100_seeds():
    runs = _runs(range(100, 200))
    covered = sum(c for _, c in runs)
    assert covered >= 95, covered
    # unbiased: the mean of 100 estimates within 3 of its sd, sqrt(p (1 - p) / 50000) = 0.0021
    assert abs(np.mean([v for v, _ in runs]) - EXACT) < 3 * 0.00207

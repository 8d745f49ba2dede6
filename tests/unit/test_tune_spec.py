"""`ema tune --spec` (and `ema design`'s tuning): an acceptance spec's limits as the tuning's
requirements.

References: the acceptance battery itself (`api.acceptance` on the same actuator and gains:
the value a requirement is judged on, computed apart from the tuning), the root of its
overshoot by scipy's brentq (the constrained optimum), and the same tuning without the spec.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from ema_cli.api.acceptance import acceptance
from ema_cli.api.tune import spec_requirements, tune
from ema_cli.config.loader import load_config
from ema_cli.config.tune import TuneConfig
from ema_cli.errors import EmaError
from ema_cli.tune.problem import INFEASIBLE, TuneProblem, build_scenarios
from ema_cli.tune.spec import measurement_violation, pick_distinct, tightened

LINEAR = {"sat1": "off", "sat2": "off", "sat3": "off"}
LIMIT = 6.0  # the spec's overshoot limit [%]
MARGIN = 0.05  # the default requirements.margin [-]
SEARCH_LIMIT = LIMIT * (1 - MARGIN)  # 5.7 %: the limit the search holds
SPEC = {"name": "one-step", "tests": {"step": {
    "test": "step", "amplitude_deg": 1.0, "duration_s": 0.3,
    "limits": {"overshoot": {"max": LIMIT, "unit": "%"}}}}}


def one_gain(**extra):
    """Kpp alone on the linear actuator, 1 deg step, ITAE over 0.3 s: the ITAE optimum is
    Kpp ~94 1/s with ~9.7 % overshoot (tests/unit/test_tune.py's brute force)."""
    doc = {"name": "one-gain", "actuator": {"plant": dict(LINEAR)},
           "simulation": {"duration_s": 0.3, "dt_s": 2e-5},
           "scenarios": {"step": {"input": {"kind": "step", "amplitude_deg": 1.0}}},
           "variables": {"Kpp": {"bounds": [20.0, 400.0], "scale": "log"}},
           "cost": {"normalise": False},
           "constraints": {"gain_margin": "off", "phase_margin": "off"},
           "optimiser": {"budget": 240, "pop": 12}}
    doc.update(extra)
    return doc


def battery_overshoot(kpp: float) -> float:
    """The overshoot [%] `ema acceptance` measures on the spec's step with Kpp = ``kpp``."""
    res = acceptance({**SPEC, "actuator": {"plant": {**LINEAR, "Kpp": float(kpp)}}})
    (row,) = res.verdicts
    assert row.measured
    return row.value


def test_limits_are_tightened_by_the_margin():
    assert tightened(-math.inf, 10.0, 0.05) == (-math.inf, 9.5)
    assert tightened(5.0, math.inf, 0.05) == (5.25, math.inf)
    assert tightened(0.0, 0.0, 0.05) == (0.0, 0.0)  # a bound of 0 stays
    assert tightened(-1.0, 1.0, 0.5) == (-0.5, 0.5)
    assert tightened(0.9, 1.0, 0.1) == (0.95, 0.95)  # bounds that would cross meet


def test_a_spec_limit_becomes_a_constraint():
    cfg = load_config(one_gain(), [], TuneConfig)
    sc, _ = build_scenarios(cfg, None)
    reqs = spec_requirements(SPEC, cfg, None)
    (req,) = reqs.requirements
    assert (req.key, req.tier, req.hi_t) == ("step: overshoot", "search",
                                            pytest.approx(SEARCH_LIMIT))  # % is SI here
    prob = TuneProblem(cfg, sc, requirements=reqs)
    ev = prob.score(np.array([[70.0], [90.0]]))
    # the battery's overshoot: 4.5 % at Kpp 70 (meets 5.7 %), 8.4 % at 90 (violates it)
    ov70, ov90 = battery_overshoot(70.0), battery_overshoot(90.0)
    assert ov70 < SEARCH_LIMIT < ov90
    assert ev.feasible.tolist() == [True, False]
    assert ev.own_feasible.tolist() == [True, True]  # the config's own constraints: none
    # penalised by its violation relative to the search's limit, as the tuning scores any
    assert ev.violation[1] == pytest.approx((ov90 - SEARCH_LIMIT) / SEARCH_LIMIT, rel=1e-9)
    assert ev.score[1] == pytest.approx(INFEASIBLE + ev.violation[1])
    assert ev.score[0] == ev.cost[0] < INFEASIBLE


def test_the_tuning_stops_at_the_spec_limit():
    # without the spec the ITAE optimum overshoots 9.7 %; with it the tuned gain sits where
    # the battery's overshoot equals the search's 5.7 % (the ITAE falls with Kpp up to ~94)
    root = brentq(lambda k: battery_overshoot(k) - SEARCH_LIMIT, 75.0, 85.0, xtol=0.01)
    assert battery_overshoot(94.0) > LIMIT  # the unconstrained optimum misses the limit
    res = tune(one_gain(), spec=SPEC)
    k = res.tuned["Kpp"]
    assert k == pytest.approx(root, rel=0.01)  # the gain within 1 % of the boundary
    assert battery_overshoot(k) <= SEARCH_LIMIT * (1 + 1e-6)  # on the feasible side
    assert res.verdict == "PASS" and res.exit_code == 0
    assert res.outcome.feasible
    df = res.requirements_frame()
    assert df.loc[0, "result"] == "PASS"
    assert df.loc[0, "tuned"] == pytest.approx(battery_overshoot(k), rel=1e-9)


def test_an_unmeetable_requirement_is_a_result_not_an_error():
    # a 1 deg step settled within 2 % in 20 ms: no Kpp in [20, 400] 1/s does (the fastest
    # settles in about 0.16 s); the tuning still returns a controller, and says so
    spec = {"name": "strict", "tests": {"step": {
        "test": "step", "amplitude_deg": 1.0, "duration_s": 0.3,
        "limits": {"settling_time": {"max": 20, "unit": "ms"}}}}}
    res = tune(one_gain(optimiser={"budget": 36, "pop": 12}), spec=spec)
    assert res.verdict == "FAIL" and res.exit_code == 1
    assert not res.outcome.feasible and res.outcome.own_feasible
    (short,) = res.shortfalls()
    assert short["requirement"] == "step: settling_time" and short["result"] == "FAIL"
    t = res.outcome.spec.tallies["step: settling_time"]
    # every controller the screening (32 Sobol points and the start) and the search measured
    assert t.met == 0 and t.seen == 33 + res.outcome.timings["evaluations"]
    assert t.best == pytest.approx(t.low) and t.best > 0.1  # [s]
    assert "none of the" in short["why"] and short["relax"].startswith("<= ")
    # named as the requirement no gains inside the bounds were found to meet, with the best
    assert short["blocking"]
    assert res.unmeetable() == (
        "no gains inside the bounds were found to meet step: settling_time <= 20 ms (best "
        f"{t.best * 1e3:.4g} ms): no PASS without relaxing these limits or changing the "
        "actuator")


def test_bad_specs_are_named():
    cfg = load_config(one_gain(), [], TuneConfig)
    with pytest.raises(EmaError, match="^spec: .*tests"):
        spec_requirements({"name": "s", "tests": {}}, cfg, None)
    with pytest.raises(EmaError, match="^spec 'nope.yaml' is not a file"):
        spec_requirements("nope.yaml", cfg, None)


def test_measurement_violation_of_bounds():
    from ema_cli.acceptance.measurement import Measurement

    measured = Measurement("m", "", 12.0, "-")
    assert measurement_violation(measured, -math.inf, 10.0) == pytest.approx(0.2)
    # a bound wholly outside the limit counts its nearest edge; straddling: at least 1
    above = Measurement("m", "", 15.0, "-", lower=15.0, upper=math.inf, reason="r")
    assert measurement_violation(above, -math.inf, 10.0) == pytest.approx(0.5)
    straddle = Measurement("m", "", 5.0, "-", lower=5.0, upper=math.inf, reason="r")
    assert measurement_violation(straddle, -math.inf, 10.0) == 1.0
    inside = Measurement("m", "", 5.0, "-", lower=0.0, upper=5.0, reason="r")
    assert measurement_violation(inside, -math.inf, 10.0) == 0.0


def test_checked_candidates_are_distinct_and_best_first():
    U = np.array([[0.5], [0.505], [0.9], [0.1], [0.51]])
    scores = np.array([1.0, 0.5, 3.0, 2.0, 0.7])
    # 0.505 best; 0.51 and 0.5 within 0.02 of it; then 0.1, then 0.9
    assert pick_distinct(U, scores, 3) == [1, 3, 2]
    assert pick_distinct(U, np.array([1.0, np.inf, np.inf, np.inf, np.inf]), 3) == [0]


def test_the_unmeetable_requirements_are_summarised_fixed_first():
    from ema_cli.tune.shortfalls import blocking_summary

    rows = [{"requirement": "rate: rate", "limit": ">= 700 deg/s", "reached": "321.1 deg/s",
             "best": "321.3 deg/s", "tier": "search", "blocking": True},
            {"requirement": "step: rise_time", "limit": "<= 80 ms", "reached": "86 ms",
             "best": "21 ms", "tier": "search", "blocking": False},
            {"requirement": "ld: free_play", "limit": "<= 0.05 deg", "reached": "0.3132 deg",
             "best": "0.3132 deg", "tier": "fixed", "blocking": True}]
    assert blocking_summary(rows) == (
        "no gains can meet ld: free_play <= 0.05 deg (0.3132 deg whatever the gains) and none "
        "inside the bounds was found to meet rate: rate >= 700 deg/s (best 321.3 deg/s): no "
        "PASS without relaxing these limits or changing the actuator")
    assert blocking_summary(rows[1:2]) == ""  # met by some controllers: not named

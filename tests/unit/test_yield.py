"""Issue 23: `ema yield`. A yield run equals, unit for unit, `ema acceptance` run on the same
sampled values (every test kind); the counts, the intervals and the JSON contract; an
INCONCLUSIVE unit is counted apart, never as a pass; adaptive N; an interrupted run resumes to
the same units; the worst case of a monotonic margin is the box's corner; the drivers' signs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ema_cli.api import acceptance
from ema_cli.api.production import production_yield
from ema_cli.errors import EmaError
from ema_cli.production.drivers import srrc
from ema_cli.production.stats import clopper_pearson

# every test kind, each as short as it can be measured (seconds in all)
ALL_KINDS = {
    "name": "every-kind",
    "actuator": {"config": None, "plant": {}, "nonlinearities": {}},
    "tests": {
        "step": {"test": "step", "amplitude_deg": 1.0, "duration_s": 0.3,
                 "limits": {"rise_time": {"max": 80, "unit": "ms"},
                            "overshoot": {"max": 10, "unit": "%"},
                            "settling_time": {"max": 0.2, "unit": "s"},
                            "steady_state_error": {"max": 0.01, "unit": "deg"},
                            "peak_current": {"max": 31, "unit": "A"}}},
        "fr": {"test": "frequency_response", "amplitudes_deg": [1.0], "f_min_hz": 2.0,
               "f_max_hz": 30.0, "n": 4, "phase_at_hz": 5.0,
               "limits": {"bandwidth": {"min": 5, "unit": "Hz"},
                          "phase_lag": {"max": 60, "unit": "deg"},
                          "peak_gain": {"max": 3, "unit": "dB"}}},
        "margins": {"test": "margins", "loops": ["position", "speed"],
                    "limits": {"gain_margin": {"min": 6, "unit": "dB"},
                               "phase_margin": {"min": 45, "unit": "deg"}}},
        "threshold": {"test": "threshold", "fraction": 0.5, "within_s": 0.05,
                      "search_deg": [1.0e-4, 1.0], "limits": {"threshold": {"max": 0.005,
                                                                         "unit": "deg"}}},
        "hysteresis": {"test": "hysteresis", "amplitude_deg": 1.0, "period_s": 1.0,
                       "set": {"controller.position_feedback": "motor"},
                       "limits": {"hysteresis": {"max": 0.5, "unit": "deg"},
                                  "free_play": {"max": 0.05, "unit": "deg"}}},
        "deflection": {"test": "load_deflection", "torque_nm": 10, "period_s": 1.0,
                       "limits": {"stiffness": {"min": 560, "unit": "N*m/rad"},
                                  "free_play": {"max": 0.05, "unit": "deg"}}},
        "stiffness": {"test": "dynamic_stiffness", "amplitude_nm": 1.0, "f_min_hz": 5.0,
                      "f_max_hz": 50.0, "n": 5,
                      "limits": {"dynamic_stiffness": {"min": 100, "unit": "N*m/rad"}}},
        "rate": {"test": "no_load_rate", "amplitude_deg": 20, "duration_s": 0.2,
                 "limits": {"rate": {"min": 700, "unit": "deg/s"}}},
    },
}
TOL = {"tolerances": {
    "plant.kL": {"dist": "normal", "mean": 590, "sd": 20},
    "nonlinearities.deadzone2": {"dist": "uniform", "low": 0.0, "high": 0.01},
    "plant.Kt": {"dist": "truncnormal", "mean": 0.08, "sd": 0.003, "low": 0.075,
                 "high": 0.085},
    "plant.Kpp": {"dist": "uniform", "low": 45.0, "high": 55.0}}}  # a controller gain too


@pytest.fixture(scope="module")
def every_kind():
    return production_yield(ALL_KINDS, TOL, n=3, seed=5, block=3, worst_budget=None)


def test_a_yield_run_equals_acceptance_unit_for_unit_on_every_kind(every_kind):
    res = every_kind
    kinds = {res.plan.spec.tests[r.test].test for r in res.plan.rows}
    assert kinds == {"step", "frequency_response", "margins", "threshold", "hysteresis",
                     "load_deflection", "dynamic_stiffness", "no_load_rate"}
    for _, unit in res.samples.iterrows():
        sets = [(f"actuator.{p}", float(unit[p])) for p in res.plan.tolerances.paths]
        one = acceptance(ALL_KINDS, sets)
        assert len(one.verdicts) == len(res.plan.rows)
        for v, r in zip(one.verdicts, res.plan.rows, strict=True):
            assert (v.test, v.metric, v.condition) == (r.test, r.metric, r.condition)
            got = unit[f"{r.label} [{r.unit}]"]
            assert got == v.value or (math.isnan(got) and math.isnan(v.value)), r.label
            assert unit[f"{r.label} result"] == v.result, r.label
        assert unit["result"] == one.verdict


def test_the_units_differ_and_the_counts_add_up(every_kind):
    res = every_kind
    assert res.samples["plant.kL"].nunique() == 3
    o = res.overall
    assert o.n == 3 and o.n_pass + o.n_fail + o.n_inconclusive == 3
    assert o.interval == clopper_pearson(o.n_pass, 3, 0.95)


def test_yield_json_has_the_contract(every_kind):
    js = every_kind.to_json()
    assert set(js["overall"]) >= {"yield", "ci_low", "ci_high", "n_pass", "n"}
    for name in ALL_KINDS["tests"]:
        assert set(js["tests"][name]) >= {"yield", "ci_low", "ci_high", "n_inconclusive"}
    assert 0.0 <= js["overall"]["ci_low"] <= js["overall"]["yield"] <= js["overall"]["ci_high"]


ONE_STEP = {"name": "one-step", "actuator": {"config": None, "plant": {},
                                              "nonlinearities": {}},
            "tests": {"step": {"test": "step", "amplitude_deg": 0.1, "duration_s": 0.3,
                               "limits": {"settling_time": {"max": 0.25, "unit": "s"}}}}}
BACKLASH = {"tolerances": {"nonlinearities.deadzone2": {"dist": "uniform", "low": 0.0,
                                                         "high": 0.004}}}


def test_an_inconclusive_unit_is_counted_apart_never_as_a_pass():
    # 0.3 s is too short for a worn unit's small step to settle: its settling time is only
    # a bound (> 0.3 s) straddling nothing -> FAIL on the bound; a limit above the run's
    # length makes such bounds INCONCLUSIVE instead
    spec = {**ONE_STEP, "tests": {"step": {**ONE_STEP["tests"]["step"],
                                           "limits": {"settling_time": {"max": 0.5,
                                                                        "unit": "s"}}}}}
    res = production_yield(spec, BACKLASH, n=12, seed=3, block=12, worst_budget=None)
    o = res.overall
    assert o.n_inconclusive > 0 and o.n_pass > 0
    assert o.value == pytest.approx(o.n_pass / 12)
    assert (res.samples["result"] == "INCONCLUSIVE").sum() == o.n_inconclusive
    assert res.to_json()["tests"]["step"]["n_inconclusive"] == o.n_inconclusive


def test_adaptive_n_stops_at_the_first_block_whose_interval_is_narrow_enough():
    # every unit passes: the half width after n units is (1 - 0.025**(1/n)) / 2
    spec = {**ONE_STEP, "tests": {"step": {**ONE_STEP["tests"]["step"],
                                           "limits": {"settling_time": {"max": 10,
                                                                        "unit": "s"}}}}}
    tol = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 5}}}
    res = production_yield(spec, tol, n=400, seed=0, block=20, target_halfwidth=0.05,
                           worst_budget=None)
    need = next(n for n in range(1, 400) if (1 - 0.025 ** (1 / n)) / 2 <= 0.05)
    assert len(res.samples) == 20 * math.ceil(need / 20)
    assert res.overall.halfwidth <= 0.05 and "reached the target" in res.stop_reason


def test_an_interrupted_run_resumes_to_the_same_units(tmp_path):
    tol = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 30}}}

    def stop_after_first(state):
        if state["n"] == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        production_yield(ONE_STEP, tol, n=8, seed=2, block=4, worst_budget=None,
                         out=tmp_path / "y", checkpoint=True, progress=stop_after_first)
    again = production_yield(ONE_STEP, tol, n=8, seed=2, block=4, worst_budget=None,
                             out=tmp_path / "y", checkpoint=True)
    assert again.resumed_units == 4
    whole = production_yield(ONE_STEP, tol, n=8, seed=2, block=8, worst_budget=None)
    cols = ["unit", "plant.kL", "step/settling_time [s]", "result"]
    assert again.samples[cols].equals(whole.samples[cols])
    folder = again.save()
    assert folder == tmp_path / "y"
    assert {"yield.json", "samples.parquet", "yield.md", "convergence.png",
            "dist_step.png", "manifest.json"} <= {p.name for p in folder.iterdir()}
    with pytest.raises(EmaError, match="never overwritten"):  # finished: not resumed
        production_yield(ONE_STEP, tol, n=8, seed=2, out=tmp_path / "y", checkpoint=True,
                         worst_budget=None)


def test_the_same_seed_gives_the_same_units_another_seed_others():
    tol = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 30}}}
    a, b, c = (production_yield(ONE_STEP, tol, n=4, seed=s, block=4, worst_budget=None,
                                drivers=False) for s in (1, 1, 2))
    assert a.samples.equals(b.samples)
    assert not np.allclose(a.samples["plant.kL"], c.samples["plant.kL"])


def test_the_worst_case_of_a_monotonic_margin_is_the_box_corner():
    # the locked-motor stiffness is kL: its worst unit is kL = mean - k sd, found exactly
    spec = {"name": "stiff", "actuator": {"config": None, "plant": {}, "nonlinearities": {}},
            "tests": {"deflection": {"test": "load_deflection", "torque_nm": 10,
                                     "period_s": 1.0, "limits": {
                                         "stiffness": {"min": 500, "unit": "N*m/rad"}}}}}
    tol = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 15},
                          "plant.Kt": {"dist": "uniform", "low": 0.076, "high": 0.084}},
           "worst_case": {"k": 2.5}}
    res = production_yield(spec, tol, n=16, seed=0, block=16, worst_budget=6)
    w = res.worst.limits["deflection/stiffness"]
    assert w["values"]["plant.kL"] == pytest.approx(590 - 2.5 * 15, rel=1e-12)
    # the measured stiffness is kL to the fit's precision over a 1 s triangle (-0.27 %)
    assert w["value"] == pytest.approx(552.5, rel=5e-3)
    assert w["margin"] == pytest.approx((w["value"] - 500) / 500, rel=1e-12)
    assert w["margin"] == pytest.approx(52.5 / 500, rel=5e-2)
    assert w["stage"] == "corner" and w["battery"] == "PASS"


def test_srrc_signs_and_ranking_of_a_known_monotonic_model():
    rng = np.random.default_rng(0)
    X = rng.random((400, 3))
    y = -3.0 * X[:, 0] ** 3 + 1.0 * X[:, 1] + 0.0 * X[:, 2] + 0.01 * rng.standard_normal(400)
    beta, r2 = srrc(X, y)
    assert beta[0] < -0.8 and 0.2 < beta[1] < 0.5 and abs(beta[2]) < 0.05
    assert r2 > 0.9


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"n": 0}, "n must be an integer >= 1"),
    ({"level": 1.0}, "level must be in"),
    ({"n": 10**7, "block": 10**7}, "block: 10000000 units of this battery"),
    ({"n": 2**31}, "n must be at most"),
    ({"target_halfwidth": 0.0}, "target_halfwidth must be in"),
    ({"method": "lhs"}, "method must be one of random, sobol"),
    ({"worst_budget": -1}, "worst_budget must be"),
    ({"seed": -1}, "seed must be an integer 0"),
])
def test_bad_arguments_are_refused_naming_them(kwargs, match):
    with pytest.raises(EmaError, match=match):
        production_yield(ONE_STEP, BACKLASH, **kwargs)


def test_a_tolerance_on_what_the_spec_sets_is_refused():
    spec = {**ONE_STEP, "actuator": {"config": None, "plant": {"kL": 600},
                                     "nonlinearities": {}}}
    tol = {"tolerances": {"plant.kL": {"dist": "normal", "mean": 590, "sd": 5}}}
    with pytest.raises(EmaError, match="actuator.plant.kL"):
        production_yield(spec, tol, n=2)

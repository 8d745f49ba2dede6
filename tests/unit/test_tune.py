"""`ema tune`: the tuning problem, its optimisers and its configs.

References: a brute-force grid (with a parabolic refinement) for a one-gain linear problem; an
independent re-simulation of the written scenario configs through `ema simulate`'s API.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ema_cli.api.simulation import simulate
from ema_cli.api.tune import tune
from ema_cli.config.loader import load_config
from ema_cli.config.tune import TuneConfig
from ema_cli.errors import EmaError
from ema_cli.tune.problem import INFEASIBLE, TuneProblem, _violation, build_scenarios
from ema_cli.tune.run import one_run, run_tuning

ROOT = Path(__file__).resolve().parents[2]
LINEAR = {"sat1": "off", "sat2": "off", "sat3": "off"}


def one_gain(**extra):
    """Kpp alone on the linear actuator, 1 deg step, ITAE over 0.3 s (an interior optimum:
    a low gain is slow, a high gain rings)."""
    doc = {"name": "one-gain", "actuator": {"plant": dict(LINEAR)},
           "simulation": {"duration_s": 0.3, "dt_s": 2e-5},
           "scenarios": {"step": {"input": {"kind": "step", "amplitude_deg": 1.0}}},
           "variables": {"Kpp": {"bounds": [20.0, 400.0], "scale": "log"}},
           "cost": {"normalise": False},
           "constraints": {"gain_margin": "off", "phase_margin": "off"},
           "optimiser": {"budget": 240, "pop": 12}}
    doc.update(extra)
    return load_config(doc, [], TuneConfig)


@pytest.fixture(scope="module")
def brute_force():
    """The ITAE-optimal Kpp of :func:`one_gain` by a 241-point log grid, refined by a parabola
    through the best grid point and its neighbours (in log Kpp)."""
    cfg = one_gain()
    sc, _ = build_scenarios(cfg, None)
    prob = TuneProblem(cfg, sc, parallel=True)
    k = np.geomspace(20.0, 400.0, 241)
    cost = prob.score(k[:, None]).cost
    i = int(np.argmin(cost))
    assert 0 < i < len(k) - 1  # interior optimum
    x = np.log(k[i - 1:i + 2])
    a, b, _ = np.polyfit(x, cost[i - 1:i + 2], 2)
    return float(np.exp(-b / (2 * a))), float(cost[i]), cfg, sc


@pytest.mark.parametrize("method", ["ga", "de"])
def test_one_gain_lands_on_the_brute_force_optimum(brute_force, method):
    k_opt, c_grid, cfg, sc = brute_force
    prob = TuneProblem(cfg, sc, parallel=True)
    res = one_run(prob, method, 240, 12, seed=1)
    k = float(prob.values(res.x[None])[0, 0])
    assert k == pytest.approx(k_opt, rel=0.01)  # the gain within 1 %
    assert res.cost <= c_grid * (1 + 1e-3)  # no worse than the best grid point
    assert res.evaluations <= 240


@pytest.mark.slow  # the slow tier: make test-all (CI runs it)
def test_the_tuned_scenarios_resimulate_to_the_reported_cost(tmp_path):
    # configs/tune.yaml at a small budget; every written scenario config re-simulated with
    # `ema simulate`'s API gives back the cost tuning.md reports
    res = tune(ROOT / "configs" / "tune.yaml", {"optimiser.budget": 96, "optimiser.pop": 32})
    out = res.save(tmp_path / "run")
    ratios = []
    for sc in res.outcome.problem.scenarios:
        tuned = simulate(out / "scenarios" / f"{sc.name}.yaml").summary["itae_pos_deg_s2"]
        default = simulate(out / "scenarios" / f"{sc.name}.default.yaml"
                           ).summary["itae_pos_deg_s2"]
        ratios.append(tuned / default)
    assert np.mean(ratios) == pytest.approx(res.cost, rel=1e-9)
    assert res.cost < 0.7 * 1.0  # the default controller's cost is 1 by construction
    for name in ("tuned.yaml", "tuning.csv", "runs.csv", "convergence.png", "tuning.md",
                 "scenario_deadband.png", "constraints.csv"):
        assert (out / name).is_file(), name
    cons = res.constraints_frame()
    assert cons["met"].all() and set(cons["constraint"]) == {
        "overshoot", "peak_current", "gain_margin", "phase_margin"}
    tuned = simulate(out / "tuned.yaml")  # the actuator with the tuned gains runs
    assert not tuned.diverged


def test_feasibility_first_scores():
    assert _violation(np.array([5.0, 12.0, np.nan]), -math.inf, 10.0) == pytest.approx(
        [0.0, 0.2, 1e6])
    assert _violation(np.array([3.0, 6.0]), 6.0, math.inf) == pytest.approx([0.5, 0.0])
    cfg = one_gain(constraints={"overshoot": {"max": 8.0, "unit": "%"},
                                "gain_margin": "off", "phase_margin": "off"})
    sc, _ = build_scenarios(cfg, None)
    prob = TuneProblem(cfg, sc)
    # Kpp 50: 3.8 % overshoot; 100: 12.1 % (lower cost, infeasible); 400: diverges
    ev = prob.score(np.array([[50.0], [100.0], [400.0]]))
    assert ev.feasible.tolist() == [True, False, False]
    assert ev.cost[1] < ev.cost[0]
    assert ev.score[0] == ev.cost[0] < INFEASIBLE < ev.score[1] < ev.score[2]
    assert ev.score[1] == pytest.approx(INFEASIBLE + (ev.constraint["overshoot"][1, 0] - 8) / 8)
    assert ev.diverged[2, 0] and not np.isfinite(ev.cost[2])


def test_runs_are_deterministic_and_report_their_spread():
    cfg = one_gain(optimiser={"budget": 36, "pop": 12, "runs": 2})
    sc, _ = build_scenarios(cfg, None)
    a = run_tuning(cfg, sc)
    b = run_tuning(cfg, sc)
    assert [r.cost for r in a.runs] == [r.cost for r in b.runs]
    assert [r.seed for r in a.runs] == [0, 1]
    assert a.cost_spread == pytest.approx(
        (max(r.cost for r in a.runs) - min(r.cost for r in a.runs))
        / min(r.cost for r in a.runs))


BASE = {"name": "t", "scenarios": {"s": {"input": {"kind": "step", "amplitude_deg": 0.1}}},
        "variables": {"Kpp": {"bounds": [10, 100]}}}


@pytest.mark.parametrize(("patch", "needles"), [
    ({"variables": {"Kpp": {"bounds": [50, 50]}}}, ["variables.Kpp", "empty bounds"]),
    ({"variables": {"Kpp": {"bounds": [100, 10]}}}, ["variables.Kpp", "above the upper"]),
    ({"variables": {"Kxx": {"bounds": [1, 2]}}}, ["variables.Kxx", "unknown variable"]),
    ({"variables": {"kL": {"bounds": [300, 900]}}}, ["variables.kL", "plant parameter"]),
    ({"variables": {"Kpp": {"bounds": [0, 10], "scale": "log"}}}, ["variables.Kpp", "> 0"]),
    ({"variables": {"fb_motor": {"bounds": [0, 2]}}}, ["variables.fb_motor", "fb_motor"]),
    ({"variables": {}}, ["variables"]),
    ({"scenarios": {}}, ["scenarios"]),
    ({"constraints": {"overshoot": {"max": -1, "unit": "%"}}},
     ["constraints.overshoot.max", "infeasible"]),
    ({"constraints": {"gain_margin": {"min": 6, "max": 3, "unit": "dB"}}},
     ["constraints.gain_margin", "above max"]),
    ({"constraints": {"overshoot": {"max": 10, "unit": "deg"}}},
     ["constraints.overshoot.unit", "percent"]),
    ({"constraints": {"wobble": {"max": 1, "unit": "deg"}}}, ["constraints.wobble", "unknown"]),
    ({"cost": {"metric": "itse"}}, ["cost.metric"]),
    ({"optimiser": {"local": "nelder-mead"}}, ["optimiser.local", "cma", "compass"]),
    ({"optimiser": {"polish": 0.95}}, ["optimiser.polish"]),
    ({"surprise": 1}, ["surprise"]),
])
def test_bad_tuning_configs_get_clear_errors(patch, needles):
    with pytest.raises(EmaError) as exc:
        load_config({**BASE, **patch}, [], TuneConfig)
    msg = str(exc.value)
    assert "\n" not in msg
    for n in needles:
        assert n in msg, msg


def test_scenario_problems_are_named():
    with pytest.raises(EmaError, match=r"scenarios\.s.*kind"):
        tune({**BASE, "scenarios": {"s": {"input": {"kind": "bump"}}}})
    with pytest.raises(EmaError, match=r"variables\.ff_sigma0.*ff_fc"):
        tune({**BASE, "variables": {"ff_sigma0": {"bounds": [1, 10]}}})
    with pytest.raises(EmaError, match=r"scenarios\.s\.plant\.Kpp.*free variable"):
        tune({**BASE, "scenarios": {"s": {"input": {"kind": "step", "amplitude_deg": 0.1},
                                          "plant": {"Kpp": 30}}}})
    with pytest.raises(EmaError, match="^budget must be an integer"):
        tune(BASE, budget=0)
    # the config's own budget below two generations: refused naming it (tune_budget tests)
    with pytest.raises(EmaError, match="^optimiser.budget 10: .*two GA generations"):
        tune({**BASE, "optimiser": {"budget": 10, "pop": 24}})
    with pytest.raises(EmaError, match="^method must be ga or de"):
        tune(BASE, method="pso")


def test_unmeetable_constraints_are_an_error_not_a_result():
    cfg = {**BASE, "simulation": {"duration_s": 0.2, "dt_s": 2e-5},
           "constraints": {"settling_time": {"max": 1, "unit": "ms"}},
           "optimiser": {"budget": 33, "pop": 12}}
    with pytest.raises(EmaError, match="no candidate met every constraint.*settling_time"):
        tune(cfg)

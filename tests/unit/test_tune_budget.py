"""`ema tune --budget`: the plan printed is what runs, a budget that cannot pay for two
generations is refused before any plan with the smallest that can, progress counts per run,
variables ending on a bound are flagged.

References: the generation arithmetic written out (GA: pop + (pop - 2 elites) per two
generations; DE: two populations of scipy's size), the optimisers' own evaluation counts."""

from __future__ import annotations

from pathlib import Path

import pytest

from ema_cli.api.tune import tune
from ema_cli.errors import EmaError
from ema_cli.optim.de import DEOptions
from ema_cli.tune.run import (
    GA_ELITES,
    check_budget,
    covers_two_generations,
    evaluations_for,
    explain_budget,
    min_budget,
    split_budget,
)

ROOT = Path(__file__).resolve().parents[2]
LINEAR = {"sat1": "off", "sat2": "off", "sat3": "off"}


def one_gain(bounds=(20.0, 400.0), **optimiser):
    """Kpp alone on the linear actuator (its ITAE optimum: Kpp ~94 1/s)."""
    return {"name": "one-gain", "actuator": {"plant": dict(LINEAR)},
            "simulation": {"duration_s": 0.3, "dt_s": 2e-5},
            "scenarios": {"step": {"input": {"kind": "step", "amplitude_deg": 1.0}}},
            "variables": {"Kpp": {"bounds": list(bounds), "scale": "log"}},
            "cost": {"normalise": False},
            "constraints": {"gain_margin": "off", "phase_margin": "off"},
            "optimiser": {"budget": 240, "pop": 12, **optimiser}}


@pytest.mark.parametrize("method", ["ga", "de"])
@pytest.mark.parametrize("pop,polish", [(64, 0.33), (16, 0.0), (24, 0.5), (8, 0.33)])
def test_the_smallest_budget_pays_for_two_generations(method, pop, polish):
    n_var = 4
    b = min_budget(method, pop, n_var, polish)
    glob, _ = split_budget(b, polish)
    if method == "ga":  # the initial population and one of offspring beside 2 elites
        need = pop + (pop - GA_ELITES)
    else:  # scipy sizes the population as a multiple of the variables
        need = 2 * DEOptions(pop=pop, budget=pop).sizes(n_var)[0]
    assert glob >= need and split_budget(b - 1, polish)[0] < need
    assert covers_two_generations(method, b, pop, n_var, polish)
    assert not covers_two_generations(method, b - 1, pop, n_var, polish)
    check_budget(method, b, pop, n_var, polish)  # accepted
    with pytest.raises(EmaError, match=f"smallest that can is {b}"):
        check_budget(method, b - 1, pop, n_var, polish)


def test_a_short_budget_is_refused_before_any_plan():
    said = []
    # configs/tune.yaml: population 64, a third of the budget for the CMA-ES polish
    with pytest.raises(EmaError) as exc:
        tune(ROOT / "configs" / "tune.yaml", budget=100, log=said.append)
    need = min_budget("ga", 64, 4, 0.33)
    msg = str(exc.value)
    assert msg.startswith("--budget 100: ") and f"the smallest that can is {need}" in msg
    # the largest population 100 pays for: 2 pop - 2 <= its share 67
    assert "a population of 34 (--set optimiser.pop=34)" in msg
    assert said == []  # nothing was announced
    assert need == 188  # 188 - round(0.33 * 188) = 126 = 64 + 62 (2 elites kept)


def test_the_accepted_budget_runs_the_generations_the_plan_says():
    said = []
    b = min_budget("ga", 12, 1, 0.33)
    res = tune(one_gain(), budget=b, log=said.append)
    plan = said[0]
    assert plan.startswith(f"budget {b} -> {evaluations_for('ga', b, 12, 1, 0.33)} "
                           "evaluations per run: GA 2 generations: 12 + 1 x 10 new")
    run = res.outcome.runs[0].result
    # two GA generations (22 evaluations), then the polish's whole iterations of 16
    assert run.history.evaluations[1] == 22
    assert run.evaluations <= evaluations_for("ga", b, 12, 1, 0.33)
    assert (run.evaluations - 22) % 16 == 0


def test_de_progress_counts_per_run():
    calls = []
    res = tune(one_gain(), method="de", runs=2, budget=60,
               progress=lambda run, done, total: calls.append((run, done, total)))
    per_run = evaluations_for("de", 60, 12, 1, 0.33)
    assert {t for _, _, t in calls} == {per_run}
    for k in (0, 1):
        mine = [d for r, d, _ in calls if r == k]
        assert mine == sorted(mine) and mine[0] > 0 and mine[-1] <= per_run
        assert mine[-1] == res.outcome.runs[k].result.evaluations
    assert "DE 3 generations" in explain_budget("de", 60, 12, 1, 0.33)


def test_variables_on_a_bound_are_flagged():
    # the ITAE optimum Kpp ~94 lies above the bounds [20, 60]: the tuned gain ends on 60
    res = tune(one_gain(bounds=(20.0, 60.0)))
    (flag,) = res.on_bounds()
    assert (flag["variable"], flag["side"], flag["bound"]) == ("Kpp", "upper", 60.0)
    assert res.tuned["Kpp"] >= 60.0 * (60.0 / 20.0) ** -0.01  # within 1 % of the log range
    assert "widen variables.Kpp.bounds" in flag["text"]
    inside = tune(one_gain())  # its optimum inside [20, 400]: no flag
    assert inside.on_bounds() == []

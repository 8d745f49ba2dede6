"""Run a tuning: one or more optimiser runs (seeds), the best kept, before/after evaluated.

The optimisers work on the unit cube of the variables (:class:`~ema_cli.tune.problem.
TuneProblem`); the GA is the project's real-coded elitist GA (``optim.ga`` preset
``improved``), DE scipy's differential evolution at the same budget (``optim.de``). Each run
starts from its own seed (``seed + k``); the reported controller is the best score over the
runs, re-scored once more (the same deterministic simulation) for the report.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.config.tune import TuneConfig
from ema_cli.optim.cmaes import default_lam
from ema_cli.optim.de import DEOptions, run_de
from ema_cli.optim.ga import GAResult, preset, run_ga
from ema_cli.optim.polish import polished
from ema_cli.tune.problem import Evaluation, Scenario, TuneProblem

GA_ELITES = 2  # elites of the tuning GA [individuals]
GA_PM = 0.2  # per-gene mutation probability of the tuning GA (few genes: about one per child)
CHECK_DT_FACTOR = 0.5  # the tuned cost is re-checked on this fraction of the step [-]


@dataclass
class RunRecord:
    """One optimiser run: its seed, result and cost."""

    seed: int
    result: GAResult
    x: np.ndarray  # variable values (SI)
    score: float
    cost: float
    feasible: bool


@dataclass
class TuneOutcome:
    """A finished tuning: the problem, every run, and the evaluations of the controllers
    compared in the report: ``reference`` (the default controller, no scenario compensators),
    ``before`` (the actuator's values of the variables, with the scenario compensators) and
    ``after`` (the tuned values), each with recorded signals."""

    cfg: TuneConfig
    problem: TuneProblem
    method: str
    runs: list[RunRecord]
    best: RunRecord
    reference: Evaluation
    before: Evaluation
    after: Evaluation
    initial: np.ndarray  # the variables' values before tuning (SI)
    check_dt: float  # the step of the convergence check [s]
    check_cost: float  # the tuned cost on that step
    wall_s: float
    timings: dict[str, float] = field(default_factory=dict)
    actuator_document: dict = field(default_factory=dict)  # the actuator's run config
    spec: Any = None
    """With an acceptance spec: its requirements (``tune.spec.SpecRequirements``)."""
    checked: list[dict[str, Any]] = field(default_factory=list)
    """With a spec: the candidates the whole battery checked after the search, best of the
    search first (``x``, ``cost``, ``violation``, ``score``, ``verdict``, ``readings``,
    ``runs``, ``verdicts``)."""
    chosen: int = 0
    """The checked candidate that became the tuned controller."""

    @property
    def feasible(self) -> bool:
        """Every constraint met (a spec's requirements included, in the search's terms)."""
        return self.best.feasible

    @property
    def own_feasible(self) -> bool:
        """The tuning config's own constraints met (a spec's requirements aside)."""
        return bool(self.after.own_feasible[0])

    @property
    def verdict(self) -> str | None:
        """With a spec: the battery's verdict on the tuned controller (PASS, FAIL or
        INCONCLUSIVE); None without one."""
        return self.checked[self.chosen]["verdict"] if self.checked else None

    @property
    def method_label(self) -> str:
        """The optimiser as a reader names it, e.g. ``GA + CMA-ES polish (last 33 %)``."""
        opt = self.cfg.optimiser
        label = self.method.upper()
        if opt.polish > 0:
            local = "CMA-ES" if opt.local == "cma" else "compass"
            label += f" + {local} polish (last {100 * opt.polish:.0f} %)"
        return label

    @property
    def cost_spread(self) -> float:
        """(largest - smallest)/smallest cost over the runs (0 for one run)."""
        c = np.array([r.cost for r in self.runs])
        return float((c.max() - c.min()) / c.min()) if np.all(np.isfinite(c)) else math.inf


def generations_for(budget: int, pop: int, elites: int = GA_ELITES) -> int:
    """GA generations (the initial one included) that spend at most ``budget`` evaluations."""
    return 1 + max((budget - pop) // (pop - elites), 0)


def _local_step(n_var: int, local: str) -> int:
    """Points per iteration of the local search: ``default_lam(n_var)`` for cma, 2*n_var for
    compass."""
    return default_lam(n_var) if local == "cma" else 2 * n_var


def _global_used(method: str, glob: int, pop: int, n_var: int) -> tuple[int, int, int]:
    """(evaluations, generations with the initial one, population members) the global
    optimiser spends of its share ``glob``."""
    if method == "de":
        members, gens = DEOptions(pop=pop, budget=max(glob, pop)).sizes(n_var)
        return members * (gens + 1), gens + 1, members
    gens = generations_for(glob, pop)
    return pop + (gens - 1) * (pop - GA_ELITES), gens, pop


def _local_iterations(budget: int, used: int, n_var: int, polish: float, local: str) -> int:
    """Whole iterations of the local search the rest of ``budget`` pays for (0 without a
    polish, or when the rest is below what ``optim.polish.polished`` needs to start)."""
    rest = budget - used
    if polish <= 0 or rest < 2 * n_var:
        return 0
    return rest // _local_step(n_var, local)


def evaluations_for(method: str, budget: int, pop: int, n_var: int, polish: float = 0.0,
                    local: str = "cma") -> int:
    """Candidate evaluations one run of ``method`` spends at most for ``budget`` (whole
    generations, then the local search's whole iterations: ``default_lam(n_var)`` points for
    cma, 2*n_var for compass)."""
    glob, _ = split_budget(budget, polish)
    used = _global_used(method, glob, pop, n_var)[0]
    return used + _local_iterations(budget, used, n_var, polish, local) * _local_step(n_var,
                                                                                      local)


def covers_two_generations(method: str, budget: int, pop: int, n_var: int,
                           polish: float = 0.0) -> bool:
    """Whether the global optimiser's share of ``budget`` pays for two whole generations (GA:
    ``pop`` + ``pop - elites`` new; DE: two of its populations)."""
    glob, _ = split_budget(budget, polish)
    if method == "de":
        members = DEOptions(pop=pop, budget=max(glob, pop)).sizes(n_var)[0]
        return glob >= 2 * members
    return glob >= 2 * pop - GA_ELITES


def min_budget(method: str, pop: int, n_var: int, polish: float = 0.0) -> int:
    """The smallest budget (evaluations per run) whose global share pays for two generations
    of the population (:func:`covers_two_generations`)."""
    b = pop
    while not covers_two_generations(method, b, pop, n_var, polish):
        b += 1
    return b


def check_budget(method: str, budget: int, pop: int, n_var: int, polish: float = 0.0,
                 option: str = "--budget", pop_option: str = "--set optimiser.pop") -> None:
    """Refuse (EmaError, one line naming ``option``) a budget that cannot pay for two
    generations of the global optimiser, with the smallest budget that can and the largest
    population this budget covers (``pop_option``); called before any plan is shown."""
    if covers_two_generations(method, budget, pop, n_var, polish):
        return
    from ema_cli.errors import EmaError

    need = min_budget(method, pop, n_var, polish)
    fits = next((p for p in range(pop - 1, 5, -1)
                 if covers_two_generations(method, budget, p, n_var, polish)), None)
    share = f" (its share after the {100 * polish:.0f} % polish)" if polish > 0 else ""
    alt = (f", or a population of {fits} ({pop_option}={fits})" if fits is not None
           else "")
    raise EmaError(f"{option} {budget}: its global search{share} cannot pay for two "
                   f"{method.upper()} generations of the population {pop}; the smallest "
                   f"that can is {need}{alt}")


def explain_budget(method: str, budget: int, pop: int, n_var: int, polish: float = 0.0,
                   local: str = "cma", patience: int = 0) -> str:
    """How ``budget`` evaluations per run become the evaluations a run spends: whole
    generations of the global optimiser on its share, then whole iterations of the local
    search (:func:`evaluations_for`), e.g. ``budget 200 -> 190 evaluations per run: ...``."""
    glob, share = split_budget(budget, polish)
    used, gens, members = _global_used(method, glob, pop, n_var)
    if method == "de":
        parts = [f"DE {gens} generations of {members} = {used} (of its {glob})"]
    else:
        stop = (f", fewer if {patience} in a row bring no improvement" if patience
                else "")
        parts = [f"GA {gens} generations: {pop} + {gens - 1} x {pop - GA_ELITES} new "
                 f"({GA_ELITES} elites kept) = {used} (of its {glob}{stop})"]
    total = used
    if polish > 0:
        step = _local_step(n_var, local)
        n_it = _local_iterations(budget, used, n_var, polish, local)
        total = used + n_it * step
        name = "CMA-ES" if local == "cma" else "compass"
        if n_it:
            parts.append(f"{name} polish up to {n_it} iterations of {step} = {n_it * step} "
                         f"(of the remaining {budget - used}; it stops once its step is "
                         "negligible)")
        else:
            parts.append(f"no {name} polish (the remaining {budget - used} cannot pay for "
                         f"one iteration of {step})")
    rest = budget - total
    tail = (f"; {rest} left unspent: only whole generations and iterations run" if rest
            else "")
    return f"budget {budget} -> {total} evaluations per run: {'; '.join(parts)}{tail}"


def split_budget(budget: int, polish: float) -> tuple[int, int]:
    """(global optimiser's share, local polish's share) of ``budget`` evaluations."""
    local = int(round(budget * polish))
    return budget - local, local


def one_run(problem: TuneProblem, method: str, budget: int, pop: int, seed: int,
            patience: int = 0, polish: float = 0.0, local: str = "cma") -> GAResult:
    """One optimiser run on ``problem`` from ``seed``: the global optimiser on its share of
    ``budget``, then the ``local`` search (``optim.polish``: cma or compass) on the rest
    (``polish`` fraction), drawing from the same generator."""
    rng = np.random.default_rng(seed)
    glob, share = split_budget(budget, polish)
    if method == "ga":
        opts = preset("improved", pop=pop, generations=generations_for(glob, pop),
                      elitism=GA_ELITES, pm=GA_PM, patience=patience)
        res = run_ga(problem, opts, rng)
    elif method == "de":
        res = run_de(problem, DEOptions(pop=pop, budget=glob), rng)
    else:
        raise ValueError(f"method must be 'ga' or 'de', got {method!r}")
    used = res.evaluations
    return polished(problem, res, budget - used, local, rng) if share > 0 else res


def run_tuning(cfg: TuneConfig, scenarios: list[Scenario], method: str | None = None,
               runs: int | None = None, budget: int | None = None,
               progress: Callable[[int, int, int], None] | None = None,
               record_dt: float | None = None, requirements: Any = None) -> TuneOutcome:
    """Tune ``cfg`` (its optimiser section, with ``method``/``runs``/``budget`` overriding).

    ``progress(run, evaluations_done, evaluations_total)`` after each generation, both counts
    of that run; ``record_dt`` the interval of the recorded signals of the before/after runs
    [s]; ``requirements`` (``tune.spec.SpecRequirements``): an acceptance spec's, screened
    before the search, measured in it, and the search's best distinct candidates checked by
    the whole battery after it (:func:`check_best`).
    """
    t0 = time.perf_counter()
    opt = cfg.optimiser
    method = method or opt.method
    n_runs = runs or opt.runs
    budget = budget or opt.budget
    check_budget(method, budget, opt.pop, len(cfg.variables), opt.polish)
    problem = TuneProblem(cfg, scenarios, requirements=requirements)
    per_run = evaluations_for(method, budget, opt.pop, len(problem.variables), opt.polish,
                              opt.local)
    if requirements is not None:
        start = np.array([scenarios[0].params[v] for v in problem.variables])
        requirements.screen(start, problem.specs, cfg.requirements.screen, opt.seed)
    records: list[RunRecord] = []
    for k in range(n_runs):
        problem.n_evaluations = 0
        if progress is not None:
            problem.progress = (lambda n, k=k: progress(k, min(n, per_run), per_run))
        seed = opt.seed + k
        res = one_run(problem, method, budget, opt.pop, seed, opt.patience, opt.polish,
                      opt.local)
        x = problem.values(res.x[None])[0]
        ev = problem.score(x[None])
        records.append(RunRecord(seed, res, x, float(ev.score[0]), float(ev.cost[0]),
                                 bool(ev.feasible[0])))
    best = min(records, key=lambda r: r.score)
    checked: list[dict[str, Any]] = []
    chosen = 0
    if requirements is not None:
        checked, chosen = check_best(problem, requirements, cfg.requirements.check)
        pick = checked[chosen]  # the battery's numbers decide (chosen > 0: not the search's best)
        best = RunRecord(best.seed, best.result, pick["x"], pick["score"], pick["cost"],
                         pick["violation"] == 0.0)
    dec = 0
    if record_dt:
        dec = max(int(round(record_dt / cfg.simulation.dt_s)), 1)
    initial = np.array([scenarios[0].params[v] for v in problem.variables])
    before = problem.score(initial[None], dec)
    after = problem.score(best.x[None], dec)
    # the default controller, scored like a candidate (its variables at the actuator's values)
    ref = problem.score(problem.reference_base[0, problem.cols][None], dec,
                        problem.reference_base)
    # convergence check: the tuned controller on half the step
    check_dt = cfg.simulation.dt_s * CHECK_DT_FACTOR
    check = TuneProblem(cfg.model_copy(update={"simulation": cfg.simulation.model_copy(
        update={"dt_s": check_dt})}), scenarios)
    check_cost = float(check.score(best.x[None]).cost[0])
    timings = {"kernel_s": problem.kernel_s, "margins_s": problem.margins_s,
               "evaluations": float(sum(r.result.evaluations for r in records))}
    if requirements is not None:
        timings.update({f"spec_{k}": v for k, v in requirements.timings.items()})
    return TuneOutcome(cfg, problem, method, records, best, ref, before, after, initial,
                       check_dt, check_cost, time.perf_counter() - t0, timings, spec=requirements,
                       checked=checked, chosen=chosen)


def check_best(problem: TuneProblem, requirements: Any, k: int) -> tuple[list[dict[str, Any]],
                                                                         int]:
    """Run the whole battery on the ``k`` best distinct candidates the search evaluated
    (``tune.spec.pick_distinct`` over ``problem.archive``) and rank them feasibility first by
    the battery's own values: the tuning config's constraints plus every requirement but the
    fixed and the unreachable ones, each against its tightened limit; among feasible ones the
    lower cost. -> (the checked candidates, best of the search first; the index of the
    chosen one)."""
    from ema_cli.tune.problem import spec_scores
    from ema_cli.tune.spec import pick_distinct

    U = np.vstack([u for u, _ in problem.archive])
    S = np.concatenate([sc for _, sc in problem.archive])
    idx = pick_distinct(U, S, k)
    X = problem.values(U[idx])
    ev = problem.score(X)
    checks = requirements.check(X)
    counted = [r for r in requirements.requirements
               if r.tier != "fixed" and r.key not in requirements.unreachable]
    out = []
    for c, chk in enumerate(checks):
        own = float(ev.own_violation[c])
        spec = sum(chk["readings"][r.key][2] for r in counted)
        cost = float(ev.cost[c])
        score = float(spec_scores(own, spec, cost))
        search_met = {r.key: bool(ev.spec[r.key].v_spec[c] == 0.0)
                      for r in requirements.by_tier("search")}
        out.append({**chk, "x": X[c], "cost": cost, "violation": own + spec,
                    "score": score, "search_score": float(S[idx[c]]),
                    "search_met": search_met})
    chosen = int(np.argmin([o["score"] for o in out]))
    return out, chosen

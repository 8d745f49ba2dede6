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

    @property
    def feasible(self) -> bool:
        return self.best.feasible

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


def evaluations_for(method: str, budget: int, pop: int, n_var: int, polish: float = 0.0,
                    local: str = "cma") -> int:
    """Candidate evaluations one run of ``method`` spends at most for ``budget`` (whole
    generations, then the local search's whole iterations: ``default_lam(n_var)`` points for
    cma, 2*n_var for compass)."""
    glob, _ = split_budget(budget, polish)
    if method == "de":
        members, gens = DEOptions(pop=pop, budget=glob).sizes(n_var)
        used = members * (gens + 1)
    else:
        used = pop + (generations_for(glob, pop) - 1) * (pop - GA_ELITES)
    if polish <= 0:
        return used
    step = default_lam(n_var) if local == "cma" else 2 * n_var
    return used + (budget - used) // step * step


def explain_budget(method: str, budget: int, pop: int, n_var: int, polish: float = 0.0,
                   local: str = "cma") -> str:
    """How ``budget`` evaluations per run become the evaluations a run spends: whole
    generations of the global optimiser on its share, then whole iterations of the local
    search (:func:`evaluations_for`), e.g. ``budget 200 -> 190 evaluations per run: ...``."""
    glob, share = split_budget(budget, polish)
    if method == "de":
        members, gens = DEOptions(pop=pop, budget=glob).sizes(n_var)
        used = members * (gens + 1)
        parts = [f"DE {gens + 1} generations of {members} = {used} (of its {glob})"]
    else:
        gens = generations_for(glob, pop)
        used = pop + (gens - 1) * (pop - GA_ELITES)
        parts = [f"GA {gens} generations: {pop} + {gens - 1} x {pop - GA_ELITES} new "
                 f"({GA_ELITES} elites kept) = {used} (of its {glob})"]
    total = used
    if polish > 0:
        step = default_lam(n_var) if local == "cma" else 2 * n_var
        n_it = (budget - used) // step
        total = used + n_it * step
        parts.append(f"{local} polish {n_it} iterations of {step} = {n_it * step} (of the "
                     f"remaining {budget - used})")
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
               record_dt: float | None = None) -> TuneOutcome:
    """Tune ``cfg`` (its optimiser section, with ``method``/``runs``/``budget`` overriding).

    ``progress(run, evaluations_done, evaluations_total)`` after each generation;
    ``record_dt`` the interval of the recorded signals of the before/after runs [s].
    """
    t0 = time.perf_counter()
    opt = cfg.optimiser
    method = method or opt.method
    n_runs = runs or opt.runs
    budget = budget or opt.budget
    if budget < 2 * opt.pop:
        from ema_cli.errors import EmaError

        raise EmaError(f"--budget: {budget} evaluations cannot cover two generations of the "
                       f"population ({opt.pop}); give at least {2 * opt.pop}")
    problem = TuneProblem(cfg, scenarios)
    per_run = evaluations_for(method, budget, opt.pop, len(problem.variables), opt.polish,
                              opt.local)
    total = n_runs * per_run
    records: list[RunRecord] = []
    for k in range(n_runs):
        done = k * per_run
        if progress is not None:
            problem.progress = (lambda n, d=done, k=k: progress(k, min(d + n, total), total))
            problem.n_evaluations = 0
        seed = opt.seed + k
        res = one_run(problem, method, budget, opt.pop, seed, opt.patience, opt.polish,
                      opt.local)
        x = problem.values(res.x[None])[0]
        ev = problem.score(x[None])
        records.append(RunRecord(seed, res, x, float(ev.score[0]), float(ev.cost[0]),
                                 bool(ev.feasible[0])))
    best = min(records, key=lambda r: r.score)
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
    return TuneOutcome(cfg, problem, method, records, best, ref, before, after, initial,
                       check_dt, check_cost, time.perf_counter() - t0, timings)

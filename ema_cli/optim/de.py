"""scipy's differential evolution at a stated budget, with the GA's problem and result shapes.

:func:`run_de` minimises the same :class:`~ema_cli.optim.ga.Problem` as :func:`~ema_cli.optim.
ga.run_ga` (bounds and a batched ``evaluate(X[n, n_par])``), with the whole population evaluated
in one call per generation (scipy's ``vectorized=True`` with ``updating="deferred"``), and
returns a :class:`~ema_cli.optim.ga.GAResult` so that reports treat both alike. The budget is
in fitness evaluations: a population of about ``pop`` (scipy sizes it as a multiple of the
number of parameters) and as many generations as the budget allows; no polish (it would spend
evaluations outside the budget, one at a time).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ema_cli.optim.ga import GAHistory, GAResult, Problem

DEFAULT_F = (0.5, 1.0)  # mutation (dithered) [-], scipy's default
DEFAULT_CR = 0.7  # crossover probability [-], scipy's default


@dataclass(frozen=True)
class DEOptions:
    """Differential evolution settings: ``pop`` population (rounded up to a multiple of the
    number of parameters, as scipy sizes it, and to at least 5 members),
    ``budget`` fitness evaluations in all (including the initial population), ``strategy``
    (scipy's name), ``mutation`` and ``recombination`` as in scipy."""

    pop: int = 32
    budget: int = 1000
    strategy: str = "best1bin"
    mutation: tuple[float, float] = DEFAULT_F
    recombination: float = DEFAULT_CR

    def __post_init__(self) -> None:
        if self.pop < 5:
            raise ValueError(f"population must be >= 5, got {self.pop}")
        if self.budget < self.pop:
            raise ValueError(f"budget ({self.budget}) must be at least one population "
                             f"({self.pop})")

    def sizes(self, n_par: int) -> tuple[int, int]:
        """(population members, generations after the initial one) for ``n_par`` parameters."""
        per = max(math.ceil(self.pop / n_par), 1)
        members = max(per * n_par, 5)
        return members, max(self.budget // members - 1, 0)


def run_de(problem: Problem, options: DEOptions, rng: np.random.Generator) -> GAResult:
    """Minimise ``problem`` with scipy's differential evolution (Latin-hypercube start), every
    generation one batched ``evaluate``; the seed is drawn from ``rng``."""
    from scipy.optimize import differential_evolution

    t0 = time.perf_counter()
    lower = np.asarray(problem.lower, dtype=np.float64)
    upper = np.asarray(problem.upper, dtype=np.float64)
    n_par = lower.shape[0]
    members, generations = options.sizes(n_par)
    best: list[float] = []
    means: list[float] = []
    xs: list[np.ndarray] = []
    evals: list[int] = []
    state = {"n": 0, "best": math.inf, "x": lower.copy()}
    ever: list[float] = []
    x_ever: list[np.ndarray] = []

    def func(xt: np.ndarray) -> np.ndarray:
        X = np.ascontiguousarray(np.atleast_2d(xt.T))  # scipy passes (n_par, n)
        cost = np.asarray(problem.evaluate(X), dtype=np.float64)
        cost = np.where(np.isnan(cost), np.inf, cost)
        state["n"] += X.shape[0]
        i = int(np.argmin(cost))
        if cost[i] < state["best"]:
            state["best"], state["x"] = float(cost[i]), X[i].copy()
        finite = cost[np.isfinite(cost)]
        best.append(float(cost[i]))
        means.append(float(finite.mean()) if finite.size else math.inf)
        xs.append(X[i].copy())
        evals.append(state["n"])
        ever.append(state["best"])
        x_ever.append(state["x"].copy())
        # scipy wants finite values for its population energies
        return np.where(np.isfinite(cost), cost, np.finfo(np.float64).max)

    differential_evolution(
        func, list(zip(lower, upper, strict=True)), strategy=options.strategy,
        maxiter=generations, popsize=members // n_par,
        mutation=options.mutation, recombination=options.recombination,
        seed=int(rng.integers(0, 2**31 - 1)), polish=False, init="latinhypercube", tol=0.0,
        atol=0.0, updating="deferred", vectorized=True)
    history = GAHistory(np.array(best), np.array(means), np.array(ever), np.array(xs),
                        np.array(x_ever), np.array(evals, dtype=np.int64))
    x = np.asarray(state["x"], dtype=np.float64)
    return GAResult(x, float(state["best"]), x.copy(), float(state["best"]), int(state["n"]),
                    len(best), False, time.perf_counter() - t0, history)

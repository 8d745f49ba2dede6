"""The local polish after a global optimiser: a batched compass (pattern) search, or CMA-ES.

From the best point found, each iteration evaluates the ``2 n`` points one step away along
each axis (in the problem's own coordinates, clipped to the bounds) in ONE batched
``evaluate`` call; the best of them replaces the centre if it is lower, else the step halves.
It stops when the budget cannot pay for another iteration or the step falls below
``min_step`` (relative to the bounds). Deterministic: no randomness.
"""

from __future__ import annotations

import time

import numpy as np

from ema_cli.optim.cmaes import cma_search
from ema_cli.optim.ga import GAHistory, GAResult, IterationLog, Problem

DEFAULT_STEP = 0.05  # first step, fraction of each variable's range [-]
DEFAULT_MIN_STEP = 1e-4  # smallest step, fraction of each range [-]


def compass_search(problem: Problem, x0: np.ndarray, f0: float, budget: int,
                   step: float = DEFAULT_STEP, min_step: float = DEFAULT_MIN_STEP
                   ) -> tuple[np.ndarray, float, GAHistory]:
    """Polish ``x0`` (cost ``f0``) with at most ``budget`` evaluations -> (x, f, history of
    the iterations; ``evaluations`` counts this search's evaluations only)."""
    lower = np.asarray(problem.lower, dtype=np.float64)
    upper = np.asarray(problem.upper, dtype=np.float64)
    span = upper - lower
    n = lower.shape[0]
    moves = np.vstack([np.eye(n), -np.eye(n)])
    x, f = np.asarray(x0, dtype=np.float64).copy(), float(f0)
    log = IterationLog(n)
    used = 0
    while used + 2 * n <= budget and step >= min_step:
        cand = np.clip(x[None, :] + step * span[None, :] * moves, lower, upper)
        fc = np.asarray(problem.evaluate(cand), dtype=np.float64)
        fc = np.where(np.isnan(fc), np.inf, fc)
        used += cand.shape[0]
        k = int(np.argmin(fc))
        if fc[k] < f:
            x, f = cand[k].copy(), float(fc[k])
        else:
            step *= 0.5
        log.add(fc, f, x, used)
    return x, f, log.history()


def polished(problem: Problem, result: GAResult, budget: int, method: str = "compass",
             rng: np.random.Generator | None = None) -> GAResult:
    """``result`` followed by a local search from its best point with ``budget`` evaluations:
    ``compass`` (this module) or ``cma`` (``optim.cmaes``, drawing from ``rng``); the histories
    joined, the counts added."""
    t0 = time.perf_counter()
    if budget < 2 * len(problem.lower):
        return result
    if method == "cma":
        x, f, h = cma_search(problem, result.x_best_ever, result.cost_best_ever, budget,
                             rng if rng is not None else np.random.default_rng(0))
    elif method == "compass":
        x, f, h = compass_search(problem, result.x_best_ever, result.cost_best_ever, budget)
    else:
        raise ValueError(f"method must be 'compass' or 'cma', got {method!r}")
    g = result.history
    n0 = int(g.evaluations[-1]) if len(g.evaluations) else 0
    hist = GAHistory(np.concatenate([g.best, h.best]), np.concatenate([g.mean, h.mean]),
                     np.concatenate([g.best_ever, h.best_ever]),
                     np.concatenate([g.x_best, h.x_best]),
                     np.concatenate([g.x_best_ever, h.x_best_ever]),
                     np.concatenate([g.evaluations, n0 + h.evaluations]))
    used = int(h.evaluations[-1]) if len(h.evaluations) else 0
    return GAResult(x, f, x.copy(), f, result.evaluations + used,
                    result.generations + len(h.best), result.stopped_early,
                    result.wall_time_s + time.perf_counter() - t0, hist)

"""A batched CMA-ES (Hansen's covariance matrix adaptation): the rotation-aware local polish.

From the best point found, each iteration samples ``lam`` points from N(m, sigma^2 C) in the
unit cube of the problem's bounds (one batched ``evaluate`` call), moves the mean to the
weighted mean of the best half and adapts the step size (cumulative step-size adaptation) and
the covariance (rank-one and rank-mu updates), with the default constants of Hansen's tutorial
("The CMA Evolution Strategy: A Tutorial", 2016). Unlike the compass search it learns a narrow
valley that is not aligned with the variables (e.g. the trade-off between the position and the
speed-loop gains) and moves along it.

Bounds: samples outside the box are clipped to it before they are evaluated and the clipped
point is what the update sees (a repair), so an optimum on a bound is reached exactly. It stops
when the budget cannot pay for another iteration or the step falls below ``min_sigma``.
Deterministic for a given ``rng``.
"""

from __future__ import annotations

import numpy as np

from ema_cli.optim.ga import GAHistory, IterationLog, Problem

DEFAULT_SIGMA = 0.1  # first step, fraction of each variable's range [-]
DEFAULT_MIN_SIGMA = 1e-6  # smallest step, fraction of each range [-]
MIN_LAM = 16  # smallest population: one chunk of the kernel's SIMD lanes per scenario [-]


def default_lam(n: int) -> int:
    """Points per iteration: Hansen's default 4 + 3 ln n (8 for 4 variables), raised to
    :data:`MIN_LAM`: a batch of the kernel costs about the same up to its lane width, and the
    larger population makes the search more robust on a rugged cost."""
    return max(MIN_LAM, 4 + int(3 * np.log(n)))


def cma_search(problem: Problem, x0: np.ndarray, f0: float, budget: int,
               rng: np.random.Generator, sigma: float = DEFAULT_SIGMA, lam: int | None = None,
               min_sigma: float = DEFAULT_MIN_SIGMA) -> tuple[np.ndarray, float, GAHistory]:
    """Polish ``x0`` (cost ``f0``) with at most ``budget`` evaluations -> (best x, its cost,
    the history of the iterations; ``evaluations`` counts this search's evaluations only)."""
    lower = np.asarray(problem.lower, dtype=np.float64)
    upper = np.asarray(problem.upper, dtype=np.float64)
    span = upper - lower
    n = lower.shape[0]
    lam = lam or default_lam(n)
    mu = lam // 2
    w = np.log(mu + 0.5) - np.log(np.arange(1, mu + 1))
    w /= w.sum()
    mueff = 1.0 / float(np.sum(w * w))
    cc = (4.0 + mueff / n) / (n + 4.0 + 2.0 * mueff / n)
    cs = (mueff + 2.0) / (n + mueff + 5.0)
    c1 = 2.0 / ((n + 1.3) ** 2 + mueff)
    cmu = min(1.0 - c1, 2.0 * (mueff - 2.0 + 1.0 / mueff) / ((n + 2.0) ** 2 + mueff))
    damps = 1.0 + 2.0 * max(0.0, np.sqrt((mueff - 1.0) / (n + 1.0)) - 1.0) + cs
    chi_n = np.sqrt(n) * (1.0 - 1.0 / (4.0 * n) + 1.0 / (21.0 * n * n))
    x_best = np.asarray(x0, dtype=np.float64).copy()
    f_best = float(f0)
    m = (x_best - lower) / span
    C = np.eye(n)
    pc = np.zeros(n)
    ps = np.zeros(n)
    log = IterationLog(n)
    used = 0
    g = 0
    while used + lam <= budget and sigma >= min_sigma:
        g += 1
        vals, B = np.linalg.eigh(C)
        D = np.sqrt(np.maximum(vals, 1e-300))
        Y = rng.standard_normal((lam, n)) @ (B * D).T
        U = np.clip(m + sigma * Y, 0.0, 1.0)
        Y = (U - m) / sigma  # the repaired steps
        fc = np.asarray(problem.evaluate(lower + span * U), dtype=np.float64)
        fc = np.where(np.isnan(fc), np.inf, fc)
        used += lam
        order = np.argsort(fc, kind="stable")
        k = int(order[0])
        if fc[k] < f_best:
            f_best, x_best = float(fc[k]), lower + span * U[k]
        y_sel = Y[order[:mu]]
        y_w = w @ y_sel
        m = m + sigma * y_w
        c_inv_sqrt = (B / D) @ B.T
        ps = (1.0 - cs) * ps + np.sqrt(cs * (2.0 - cs) * mueff) * (c_inv_sqrt @ y_w)
        norm_ps = float(np.linalg.norm(ps))
        h_sig = norm_ps / np.sqrt(1.0 - (1.0 - cs) ** (2 * g)) / chi_n < 1.4 + 2.0 / (n + 1.0)
        pc = (1.0 - cc) * pc + h_sig * np.sqrt(cc * (2.0 - cc) * mueff) * y_w
        C = ((1.0 - c1 - cmu) * C
             + c1 * (np.outer(pc, pc) + (1.0 - h_sig) * cc * (2.0 - cc) * C)
             + cmu * (y_sel.T * w) @ y_sel)
        C = 0.5 * (C + C.T)
        sigma *= float(np.exp((cs / damps) * (norm_ps / chi_n - 1.0)))
        log.add(fc, f_best, x_best, used)
    return x_best, f_best, log.history()

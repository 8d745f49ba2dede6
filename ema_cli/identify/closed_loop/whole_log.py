"""Single shooting over the whole log: the batched finite-difference Jacobian of the weighted
residuals and the bounded least-squares polish (used by the GA search's continuation and as
the multiple-shooting fit's whole-log check)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ema_cli.identify.closed_loop.problem import ClosedLoopProblem

FD_REL_STEP = 1e-4  # central-difference step, relative to max(|x|, 1e-3*(hi - lo)) [-]
POLISH_TOL = 1e-10  # xtol/ftol/gtol of the least-squares polish [-]


def fd_jacobian(problem: ClosedLoopProblem, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Central-difference Jacobian of the weighted residuals at ``x`` -> (r(x), J[N, p]); the
    base point and the 2p perturbed sets run in one kernel call (one-sided at a bound)."""
    p = x.shape[0]
    h = FD_REL_STEP * np.maximum(np.abs(x), 1e-3 * (problem.upper - problem.lower))
    up = np.minimum(x + h, problem.upper)
    dn = np.maximum(x - h, problem.lower)
    X = np.repeat(x[None], 2 * p + 1, axis=0)
    for j in range(p):
        X[1 + j, j] = up[j]
        X[1 + p + j, j] = dn[j]
    R = problem.weighted_residuals(X)
    J = (R[1:1 + p] - R[1 + p:]).T / (up - dn)[None, :]
    return R[0], J


def polish(problem: ClosedLoopProblem, x0: np.ndarray, max_iter: int) -> tuple[Any, int]:
    """Bounded TRF least squares from ``x0`` in bound-scaled variables -> (scipy result, jacs)."""
    from scipy.optimize import least_squares

    lo, hi = problem.lower, problem.upper
    span = hi - lo
    cache: dict[bytes, np.ndarray] = {}
    njev = 0

    def fun(u: np.ndarray) -> np.ndarray:
        x = lo + u * span
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = problem.weighted_residuals(x[None])[0]
        return cache[key]

    def jac(u: np.ndarray) -> np.ndarray:
        nonlocal njev
        njev += 1
        _, J = fd_jacobian(problem, lo + u * span)
        return J * span[None, :]

    u0 = np.clip((x0 - lo) / span, 0.0, 1.0)
    res = least_squares(fun, u0, jac=jac, bounds=(0.0, 1.0), method="trf", x_scale=1.0,
                        xtol=POLISH_TOL, ftol=POLISH_TOL, gtol=POLISH_TOL,
                        max_nfev=max_iter)
    res.x = lo + res.x * span
    return res, njev


__all__ = ["FD_REL_STEP", "POLISH_TOL", "fd_jacobian", "polish"]

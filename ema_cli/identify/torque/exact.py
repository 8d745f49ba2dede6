"""The least-squares certificate: the global optimum of Eq. 8 by variable projection.

For a fixed alpha the torque is linear in kL and c, so the cost can be minimised over them in
closed form; what is left is a 1-D profile ``Jp(alpha) = min_{kL[, c]} J`` searched on a grid
over the alpha range, refined by a bounded Brent search and polished with
``scipy.optimize.least_squares`` on all parameters (analytic Jacobian).

* ``paper`` form: ``T = kL*DZ(dth, alpha) + c*dw`` is exactly linear in (kL, c); the closed form
  is the 1- or 2-column normal equations.
* ``contact`` form: ``T = kL*DZ + c*clip(dw, -pen/tau, pen/tau)`` in contact (pen = |dth| -
  alpha; the clipped rate depends on alpha only, so T is still linear in (kL, c)); the clamp
  (the torque never pulls) makes the model piecewise linear. For a fixed alpha we iterate on
  the active set (samples in contact whose linear torque has the pushing sign): solve the
  normal equations on the active samples, recompute the set, repeat.
  The best true J seen is kept; the final ``least_squares`` polish works on the true residuals.

Uncertainty: with residual variance ``s^2 = J/(n - p)`` and residual Jacobian ``A[n, p]`` at the
optimum, ``cov = s^2 (A^T A)^-1``; standard errors are ``sqrt(diag(cov))``. This assumes white
residuals; with coloured (e.g. model-mismatch) residuals the errors are optimistic.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from ema_cli._numba import njit
from ema_cli.identify.torque.problem import TorqueProblem
from ema_cli.model.transmission import inverse_tau, shaft_torque_nb

GRID_POINTS = 201  # alpha grid of the profile over the search range [points]
ACTIVE_SET_ITERS = 30  # contact form: active-set iterations per alpha [-]
BRENT_XATOL_REL = 1e-10  # Brent tolerance on alpha, relative to the range width [-]
LSQ_TOL = 1e-15  # least_squares ftol/xtol/gtol (polish to machine precision) [-]
SINGULAR_RCOND = 1e-12  # normal matrices with reciprocal condition below this are singular [-]
BOUND_TOL_REL = 1e-9  # alpha within this fraction of the range width of a bound is "on" it [-]


@dataclass
class ExactResult:
    """The least-squares optimum of Eq. 8 and its uncertainty.

    x[n_par]          optimum in ``names`` order (kL [N*m/rad], alpha [rad], c [N*m*s/rad])
    cost              J at x [N^2*m^2]
    se[n_par]         standard errors (same units as x; NaN if the Jacobian is singular)
    cov[n_par, n_par] covariance
    corr_k_alpha      correlation of kL and alpha estimates [-]
    alpha_grid, profile   the profile Jp(alpha) on the grid (for plots)
    at_bound          True when alpha lies on a bound of its range
    """

    names: tuple[str, ...]
    x: np.ndarray
    cost: float
    se: np.ndarray
    cov: np.ndarray
    corr_k_alpha: float
    n_samples: int
    nfev: int
    wall_time_s: float
    at_bound: bool
    alpha_grid: np.ndarray = field(repr=False)
    profile: np.ndarray = field(repr=False)

    @property
    def params(self) -> dict[str, float]:
        """The optimum as {name: value}."""
        return {n: float(v) for n, v in zip(self.names, self.x, strict=True)}


@njit(cache=True, entry=True)
def profile_nb(alphas, dth, dw, tq, c_fixed, fit_c, contact, inv_tau, max_iter, j_out, x_out):
    """Profile kernel: for each alpha, kL (and c) in closed form -> j_out[G], x_out[G, n_par].

    Paper form: one solve of the normal equations. Contact form (alpha > 0): active-set
    iterations, the active samples being those in contact whose linear torque at the previous
    iterate pushes (the first iterate uses every contact sample); the best true J is kept.
    """
    n = dth.shape[0]
    for g in range(alphas.shape[0]):
        a = alphas[g]
        clamp = contact and a > 0.0
        best, bk, bc = np.inf, np.nan, np.nan
        kp, cp, have_prev = 0.0, 0.0, False
        for _ in range(max_iter):
            s11 = s12 = s22 = b1 = b2 = 0.0
            for i in range(n):
                d = dth[i]
                if d > a:
                    z = d - a
                elif d < -a:
                    z = d + a
                else:
                    z = 0.0
                    if clamp:
                        continue
                lim = (abs(d) - a) * inv_tau
                wv = min(max(dw[i], -lim), lim) if clamp else dw[i]
                if clamp and have_prev:
                    lin = kp * z + cp * wv
                    if (d > 0.0 and lin <= 0.0) or (d < 0.0 and lin >= 0.0):
                        continue
                if fit_c:
                    s11 += z * z
                    s12 += z * wv
                    s22 += wv * wv
                    b1 += z * tq[i]
                    b2 += wv * tq[i]
                else:
                    s11 += z * z
                    b1 += z * (tq[i] - c_fixed * wv)
            if fit_c:
                det = s11 * s22 - s12 * s12
                if not det > SINGULAR_RCOND * s11 * s22:
                    break
                k = (s22 * b1 - s12 * b2) / det
                c = (s11 * b2 - s12 * b1) / det
            else:
                if not s11 > 0.0:
                    break
                k = b1 / s11
                c = c_fixed
            jsum = 0.0
            changes = 0
            for i in range(n):
                d = dth[i]
                r = tq[i] - shaft_torque_nb(k, a, c, contact, inv_tau, 0.0, 0.0, d, dw[i], 0.0)
                jsum += r * r
                if clamp and have_prev and (d > a or d < -a):
                    z = d - a if d > a else d + a
                    lim = (abs(d) - a) * inv_tau
                    wv = min(max(dw[i], -lim), lim)
                    on_prev = (kp * z + cp * wv) * d > 0.0
                    on_new = (k * z + c * wv) * d > 0.0
                    if on_prev != on_new:
                        changes += 1
            if jsum < best:
                best, bk, bc = jsum, k, c
            if not clamp or (have_prev and changes == 0):
                break
            kp, cp, have_prev = k, c, True
        j_out[g] = best
        x_out[g, 0] = bk
        x_out[g, 1] = a
        if fit_c:
            x_out[g, 2] = bc


def profile(problem: TorqueProblem, alphas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Profile cost and the linear parameters at each alpha -> (Jp[G], X[G, n_par])."""
    alphas = np.ascontiguousarray(np.atleast_1d(alphas), dtype=np.float64)
    J = np.empty(alphas.shape[0])
    X = np.empty((alphas.shape[0], len(problem.names)))
    profile_nb(alphas, problem.dth, problem.dw, problem.torque, float(problem.c_fixed),
               problem.fit_c, problem.form == "contact", inverse_tau(float(problem.tau)),
               ACTIVE_SET_ITERS, J, X)
    return J, np.where(np.isfinite(J)[:, None], X, np.nan)


def _jacobian(problem: TorqueProblem, x: np.ndarray) -> np.ndarray:
    """d(residual)/dx [n, n_par] (residual = T_meas - T_model)."""
    p = problem.full_params(x)
    d, w = problem.dth, problem.dw
    outside = np.abs(d) > p["alpha"]
    dz = np.sign(d) * np.maximum(np.abs(d) - p["alpha"], 0.0)
    if problem.form == "contact" and p["alpha"] > 0.0:
        tau = float(problem.tau)
        lim = (np.abs(d) - p["alpha"]) / tau if tau > 0.0 else np.full(d.shape, np.inf)
        wr = np.clip(w, -lim, lim)  # the damped rate (the limit only matters in contact)
        limited = np.abs(w) > lim  # there d wr / d alpha = -sign(w)/tau
        lin = p["kL"] * dz + p["c"] * wr
        active = outside & (lin * np.sign(d) > 0.0)
        d_alpha = -p["kL"] * np.sign(d)
        if tau > 0.0:
            d_alpha = d_alpha - p["c"] * np.sign(w) * limited / tau
        cols = [dz * active, d_alpha * active]
        if problem.fit_c:
            cols.append(wr * active)
    else:
        cols = [dz, -p["kL"] * np.sign(d) * outside]
        if problem.fit_c:
            cols.append(w)
    return -np.column_stack(cols)


def covariance(problem: TorqueProblem, x: np.ndarray, cost: float) -> tuple[np.ndarray, float]:
    """(cov, corr_kL_alpha): cov = s^2 (A^T A)^-1 with s^2 = J/(n - p); NaN when singular.

    The correlation comes from ``(A^T A)^-1`` alone, so it is defined on noise-free data too
    (where J = 0 and every standard error is 0).
    """
    A = _jacobian(problem, x)
    n, p = A.shape
    AtA = A.T @ A
    dof = max(n - p, 1)
    d = np.sqrt(np.diag(AtA))  # scale the columns: kL, alpha and c differ by ~1e6 in size
    try:
        if not np.all(d > 0):
            raise np.linalg.LinAlgError
        C = AtA / np.outer(d, d)
        if not np.linalg.cond(C) * SINGULAR_RCOND < 1.0:
            raise np.linalg.LinAlgError
        inv = np.linalg.inv(C) / np.outer(d, d)
    except np.linalg.LinAlgError:
        return np.full((p, p), np.nan), float("nan")
    corr = float(inv[0, 1] / np.sqrt(inv[0, 0] * inv[1, 1]))
    return (cost / dof) * inv, corr


def solve_exact(
    problem: TorqueProblem, grid_points: int = GRID_POINTS
) -> ExactResult:
    """The global least-squares optimum of ``problem`` over alpha in its bounds.

    kL and c are unconstrained (closed form); alpha is searched within
    ``[problem.lower[1], problem.upper[1]]``.
    """
    t0 = time.perf_counter()
    lo, hi = float(problem.lower[1]), float(problem.upper[1])
    grid = np.linspace(lo, hi, grid_points)
    Jg, Xg = profile(problem, grid)
    nfev = grid_points
    if not np.any(np.isfinite(Jg)):
        raise ValueError("the least-squares problem is singular over the whole alpha range")
    i = int(np.argmin(Jg))
    best_x, best_J = Xg[i].copy(), float(Jg[i])

    # Brent on the profile between the grid neighbours of the best point
    a_lo, a_hi = grid[max(i - 1, 0)], grid[min(i + 1, grid_points - 1)]

    def jp(a: float) -> float:
        return float(profile(problem, np.array([a]))[0][0])

    br = minimize_scalar(jp, bounds=(a_lo, a_hi), method="bounded",
                         options={"xatol": BRENT_XATOL_REL * (hi - lo)})
    nfev += int(br.nfev)
    if br.fun < best_J:
        Jb, Xb = profile(problem, np.array([br.x]))
        best_x, best_J = Xb[0].copy(), float(Jb[0])

    # polish all parameters on the true residuals
    span = problem.upper - problem.lower
    lower = np.full(best_x.shape, -np.inf)
    upper = np.full(best_x.shape, np.inf)
    lower[1], upper[1] = lo, hi
    x0 = np.clip(best_x, lower, upper)
    try:
        ls = least_squares(problem.residuals, x0, jac=lambda x: _jacobian(problem, x),
                           bounds=(lower, upper), x_scale=span, ftol=LSQ_TOL, xtol=LSQ_TOL,
                           gtol=LSQ_TOL, method="trf")
        nfev += int(ls.nfev)
        J_ls = float(np.sum(problem.residuals(ls.x) ** 2))
        if J_ls <= best_J:
            best_x, best_J = ls.x.copy(), J_ls
    except ValueError:
        pass  # the profile result stands

    cov, corr = covariance(problem, best_x, best_J)
    se = np.sqrt(np.abs(np.diag(cov)))
    tol = BOUND_TOL_REL * (hi - lo)
    at_bound = bool(best_x[1] <= lo + tol or best_x[1] >= hi - tol)
    return ExactResult(problem.names, best_x, best_J, se, cov, corr, problem.n_samples, nfev,
                       time.perf_counter() - t0, at_bound, grid, Jg)

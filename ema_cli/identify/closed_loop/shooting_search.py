"""The search of the multiple-shooting fit (:mod:`ema_cli.identify.closed_loop.shooting`): segment
states
seated (:mod:`ema_cli.identify.closed_loop.shooting_seat`), then Levenberg-Marquardt on
the free parameters and every segment state together, many starts at once (one kernel call per
Jacobian and per round of trial steps), with successive halving of the starts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.identify.closed_loop.problem import ClosedLoopProblem
from ema_cli.identify.closed_loop.shooting import NV, ShootingProblem
from ema_cli.identify.closed_loop.shooting_seat import (
    chain_seat,
    fit_states,
    reconstruct,
    seg_costs,
    start_states,  # noqa: F401  (kept here: callers reach it as shooting_search.start_states)
    state_starts,
)

RESEAT_RATIO = 1.5  # re-seat the segments whose cost exceeds this x the median segment's [-]
LM_TRIES = 8  # damping increases per LM iteration before a start is declared converged
LM_UP, LM_DOWN = 10.0, 5.0  # damping factors after a rejected / accepted step [-]
GN_LAMBDA = 1e-3  # a step with at most this Marquardt damping is nearly Gauss-Newton [-]
CHI2_TOL = 0.01
"""A start has converged when a nearly Gauss-Newton step lowers its cost by less than this
many residuals' worth (chi-square units at the noise level) [-]."""
STALL_MOVE_CHI2 = 1.0
"""A re-seat of a stalled start counts as a move (the start goes on) only when it lowers the
cost by more than this many residuals' worth [-]: measured on two battery logs, 26 of the 32
repeated re-seats of a start moved the cost by less than 0.2 residuals' worth (the other 6 by
2.1 to 9.5, which still go on), each one a full re-fit of every segment (1.1 s at the search's
step, 4.7 s at the fine one for a 4 s log)."""
JAC_EVERY = 2
"""A start's finite-difference Jacobian is computed every this many LM iterations, and
carried along the accepted steps between (:func:`broyden`) [-]. The Jacobian is 1 + p + NV
kernel lanes per segment (11 to 14), a trial step one. Measured: 3 to 8 % of a fit's kernel
work (the README's example, unstated battery log03, stated log07); on stated log07 the
refinement at the fine step on carried Jacobians stopped with one segment in a wrong minimum
(J/N 3.4, reported not confirmed) where fresh ones confirm the fit (docs/identification.md)."""
STALL_WINDOW = 3
STALL_CHI2 = 0.1
"""A start has stopped moving when its cost fell by less than :data:`STALL_CHI2` residuals'
worth (chi-square units at the noise level: a tenth of one, where a parameter's standard error
is one) over its last :data:`STALL_WINDOW` iterations, whatever the damping [-]. Measured on
the README's example and an unstated battery log: the lengthening and the refinement ran to
their caps (20, 15 iterations) and the search's last round to its 60 creeping down by 0.01 to
0.05 residuals' worth an iteration (a step that is not nearly Gauss-Newton never stopped a
start), 0.2 to 0.4 of one in all over the last 10 to 30 iterations."""


STATE_BAND = 2 * NV - 1
"""The half-bandwidth of the segment states' block of the normal equations: each segment's
states touch only their own residuals (a block of NV on the diagonal), and the motor-angle
tie couples each segment with the next (the blocks beside it) [-]."""


def lm_step(A: np.ndarray, g: np.ndarray, damping: np.ndarray, p: int) -> np.ndarray:
    """The Levenberg-Marquardt step ``-(A + diag(damping))^-1 g`` of the joint fit (``p``
    parameters first, then every segment's states), solved by its structure: the states'
    block is banded (:data:`STATE_BAND`), so it is eliminated by a banded Cholesky
    factorisation and only the parameters' p x p Schur complement is solved densely
    (O(n_vars * band^2) instead of the dense O(n_vars^3): a 4 s log on 0.05 s segments has
    487 unknowns). Falls back to the dense solve when the states' block is not numerically
    positive definite. Raises ``numpy.linalg.LinAlgError`` when that fails too."""
    from scipy.linalg import cho_solve_banded, cholesky_banded

    M = A + np.diag(damping)
    n = M.shape[0]
    ns = n - p
    u = min(STATE_BAND, ns - 1)
    if ns <= 0 or u < 0:
        return -np.linalg.solve(M, g)
    S = M[p:, p:]
    ab = np.zeros((u + 1, ns))
    for k in range(u + 1):  # upper form: ab[u - k, k:] is the k-th superdiagonal
        ab[u - k, k:] = np.diagonal(S, k)
    B = M[:p, p:]
    try:
        c = cholesky_banded(ab, lower=False)
        X = cho_solve_banded((c, False), np.column_stack([B.T, g[p:]]))
    except (np.linalg.LinAlgError, ValueError):
        return -np.linalg.solve(M, g)
    XB, Xg = X[:, :p], X[:, p]
    dp = np.linalg.solve(M[:p, :p] - B @ XB, B @ Xg - g[:p])
    return np.concatenate([dp, -Xg - XB @ dp])


@dataclass
class LMState:
    """Batched Levenberg-Marquardt over several starts (scaled unknowns ``V[m, n_vars]``)."""

    V: np.ndarray
    cost: np.ndarray
    R: np.ndarray
    lam: np.ndarray
    active: np.ndarray
    iterations: np.ndarray
    reseated: np.ndarray  # re-seated since it last moved (a second stall ends it)
    history: list[np.ndarray] = field(default_factory=list)


def reseat(sp: ShootingProblem, st: LMState, dt: float, which: np.ndarray,
           iterations: int = 6, ratio: float = RESEAT_RATIO) -> None:
    """Re-fit the segment states of the starts ``which`` that fit clearly worse than the
    start's median segment (cost above ``ratio`` x it; ``ratio`` 0: every segment, for a
    stalled start) from starts across the gap (for their current parameters), and keep each
    segment's new state where it fits better. Only those segments are simulated."""
    if which.size == 0:
        return
    c1 = seg_costs(sp, st.R[which])
    # only the segments that fit clearly worse than the start's typical segment
    suspect = c1 > ratio * np.median(c1, axis=1, keepdims=True)
    rows = np.any(suspect, axis=1)
    which, c1, suspect = which[rows], c1[rows], suspect[rows]
    if which.size == 0:
        return
    X, starts, group = [], [], []
    at = sp.seg.first
    for g, i in enumerate(which):
        x, S = sp.unpack(st.V[i])
        recs = [S]
        if ratio <= 0.0:  # a stalled start: also from the reconstructions of the data
            recs += [reconstruct(sp.base, x, at), reconstruct(sp.base, x, at, True)]
        for S0 in state_starts(sp, x, recs):
            X.append(x)
            starts.append(S0)
            group.append(g)
    S2, c2 = fit_states(sp, np.array(X), np.array(starts), np.array(group), dt, iterations,
                        prune_after=3, which=suspect)
    for g, i in enumerate(which):
        better = c2[g] < c1[g] * (1.0 - 1e-9)
        if np.any(better):
            x, S = sp.unpack(st.V[i])
            S[better] = S2[g][better]
            st.V[i] = sp.pack(x, S)
    R, _ = sp.residuals_many(st.V[which], dt)
    st.R[which] = R
    st.cost[which] = np.sum(R**2, axis=1)


def broyden(sp: ShootingProblem, jac: tuple[np.ndarray, np.ndarray, np.ndarray],
            dv: np.ndarray, dr: np.ndarray) -> None:
    """Carry a start's compact Jacobian ``jac = (r, Jx, Js)`` (:meth:`ShootingProblem.
    jacobian_many`) along its step ``dv`` (scaled unknowns) that changed the residuals by
    ``dr``, in place: Schubert's sparse Broyden update, one secant condition per segment (a
    segment's data residuals depend on the parameters and its own states only, so each
    segment's rows take the rank-one correction of its own part of the step, and the compact
    structure stays). The tie's rows keep their parameter columns (their state columns are
    analytic: :meth:`ShootingProblem.tie_state_jacobian`)."""
    p, nd = sp.p, sp.n_data
    _, Jx, Js = jac
    owner = np.tile(sp._gather()[0], len(sp.base.channels))
    dp = dv[:p]
    dS = dv[p:].reshape(sp.seg.n, NV)
    dSr = dS[owner]  # [nd, NV]: each data row's own segment's state step
    err = dr[:nd] - Jx[:nd] @ dp - np.einsum("ik,ik->i", Js[:nd], dSr)
    norm = float(dp @ dp) + np.sum(dS**2, axis=1)
    w = np.where(norm[owner] > 0.0, err / np.where(norm[owner] > 0.0, norm[owner], 1.0), 0.0)
    Jx[:nd] += w[:, None] * dp[None, :]
    Js[:nd] += w[:, None] * dSr


def lm_many(sp: ShootingProblem, st: LMState, dt: float, max_iter: int,
            reseat_every: int = 5, tol: float = 1e-9, chi2_tol: float = CHI2_TOL,
            progress: Any = None, stall_ratio: float = 0.0,
            stall_chi2: float = STALL_CHI2, jac_every: int = JAC_EVERY) -> LMState:
    """Levenberg-Marquardt on the free parameters and every segment state together, for all
    active starts at once: per iteration ONE kernel call for all their Jacobians and one per
    round of trial steps (each start with its own damping, Marquardt's diagonal scaling;
    parameters clipped to their bounds). A start's Jacobian is computed by finite differences
    every ``jac_every`` iterations (:data:`JAC_EVERY`) and carried along its accepted steps in
    between (:func:`broyden`); an iteration on a carried Jacobian that finds no step, or a
    step that would stop the start, hands the decision to a fresh Jacobian in the next
    (with the damping as it was), so a start stops, stalls or is re-seated only on a fresh
    one, as before. Every ``reseat_every`` iterations the segment
    states are re-seated (:func:`reseat`). A start stops when no damping lowers its cost or
    its relative decrease is below ``tol``, or when a nearly Gauss-Newton step (damping at
    most :data:`GN_LAMBDA`) lowers it by less than ``chi2_tol`` residuals' worth (``chi2_tol
    * cost / n_residuals``: with residuals at the noise level, ``chi2_tol`` in chi-square
    units, a tenth of a standard error from the optimum of the local quadratic model). A
    stalled start is re-seated once (``stall_ratio`` 0: every segment, also from the data's
    reconstructions; else the segments above ``stall_ratio`` x the median segment's cost) and
    goes on only if that lowered its cost by more than :data:`STALL_MOVE_CHI2` residuals'
    worth. A start whose cost fell by less than ``stall_chi2`` residuals' worth over its last
    :data:`STALL_WINDOW` iterations of this call stops too (:data:`STALL_CHI2`)."""
    p = sp.p
    n_res = max(sp.base.measured.size, 1)
    lo = np.concatenate([np.zeros(p), np.full(sp.n_vars - p, -np.inf)])
    hi = np.concatenate([np.ones(p), np.full(sp.n_vars - p, np.inf)])
    trace = [st.cost.copy()]  # each start's cost before this call's iterations, after each
    jac: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # per start (r, Jx, Js)
    since = np.full(st.V.shape[0], jac_every)  # iterations since its Jacobian was computed
    for it in range(1, max_iter + 1):
        act = np.flatnonzero(st.active)
        if act.size == 0:
            break
        if reseat_every and it % reseat_every == 0:
            reseat(sp, st, dt, act)
            V2, R2, c2 = chain_seat(sp, st.V[act], dt)
            moved = c2 < st.cost[act]
            st.V[act[moved]], st.R[act[moved]], st.cost[act[moved]] = (V2[moved], R2[moved],
                                                                      c2[moved])
            since[act] = jac_every  # the states moved: a Jacobian of their own
        fresh_now = since[act] >= jac_every
        need = act[fresh_now]
        if need.size:
            R0, Jx, Js = sp.jacobian_many(st.V[need], dt)
            for q, i in enumerate(need):
                jac[i] = (R0[q], Jx[q], Js[q])
            since[need] = 0
        lam_was_it = st.lam.copy()
        AG = [sp.normal_equations(jac[i][0] if f else st.R[i], jac[i][1], jac[i][2], st.V[i])
              for i, f in zip(act, fresh_now, strict=True)]
        A = np.array([a for a, _ in AG])
        g = np.array([b for _, b in AG])
        d = np.einsum("ijj->ij", A).copy()
        d[d <= 0] = 1.0
        pending = list(range(act.size))
        for _ in range(LM_TRIES):
            if not pending:
                break
            trials = []
            for q in pending:
                i = act[q]
                try:
                    dv = lm_step(A[q], g[q], st.lam[i] * d[q], p)
                except np.linalg.LinAlgError:
                    dv = np.zeros(sp.n_vars)
                trials.append(np.clip(st.V[i] + dv, lo, hi))
            Rt, _ = sp.residuals_many(np.array(trials), dt)
            ct = np.sum(Rt**2, axis=1)
            still = []
            for k, q in enumerate(pending):
                i = act[q]
                if ct[k] < st.cost[i]:
                    rel = (st.cost[i] - ct[k]) / max(st.cost[i], 1e-300)
                    lam_was = st.lam[i]
                    if jac_every > 1:  # the Jacobian carried to the new point
                        broyden(sp, jac[i], trials[k] - st.V[i], Rt[k] - st.R[i])
                    st.V[i], st.R[i], st.cost[i] = trials[k], Rt[k], ct[k]
                    st.lam[i] = max(st.lam[i] / LM_DOWN, 1e-12)
                    if rel < tol or (lam_was <= GN_LAMBDA and rel * n_res < chi2_tol):
                        if fresh_now[q]:
                            st.active[i] = False
                        else:  # judged on an updated Jacobian: a fresh one decides
                            since[i] = jac_every
                else:
                    st.lam[i] *= LM_UP
                    still.append(q)
            pending = still
        if pending:  # on an updated Jacobian: a fresh one, the damping as it was
            upd = np.array([not fresh_now[q] for q in pending])
            late = act[np.array(pending)[upd]] if np.any(upd) else np.zeros(0, dtype=int)
            st.lam[late] = lam_was_it[late]
            since[late] = jac_every
            pending = [q for q in pending if fresh_now[q]]
        if pending:  # no damping lowered the cost: re-seat every segment state once first
            stuck = act[np.array(pending)]
            fresh = stuck[~st.reseated[stuck]]
            before = st.cost[fresh].copy()
            reseat(sp, st, dt, fresh, ratio=stall_ratio)
            if fresh.size:
                st.V[fresh], st.R[fresh], st.cost[fresh] = chain_seat(sp, st.V[fresh], dt)
            st.reseated[fresh] = True
            since[fresh] = jac_every
            for i, c in zip(fresh, before, strict=True):
                if c - st.cost[i] > max(1e-6 * c, STALL_MOVE_CHI2 * c / n_res):
                    st.lam[i] = 1e-3
                    st.reseated[i] = False  # moved: may re-seat again when stuck again
                else:
                    st.active[i] = False
            st.active[stuck[st.reseated[stuck] & ~np.isin(stuck, fresh)]] = False
        st.iterations[act] += 1
        since[act] += 1
        trace.append(st.cost.copy())
        if stall_chi2 > 0.0 and len(trace) > STALL_WINDOW:
            fell = trace[-1 - STALL_WINDOW][act] - st.cost[act]
            st.active[act[fresh_now & (fell < stall_chi2 * st.cost[act] / n_res)]] = False
        st.history.append(st.cost.copy())
        if progress is not None:
            progress(it, max_iter, float(np.min(st.cost)))
    return st


def new_state(sp: ShootingProblem, V: np.ndarray, dt: float) -> LMState:
    """An :class:`LMState` for starts ``V[m, n_vars]`` (residuals evaluated)."""
    R, _ = sp.residuals_many(V, dt)
    m = V.shape[0]
    return LMState(V.copy(), np.sum(R**2, axis=1), R, np.full(m, 1e-3), np.ones(m, bool),
                   np.zeros(m, dtype=np.int64), np.zeros(m, bool))


HALVING = ((10, 0.5), (10, 0.75))
"""Successive halving of the starts: (LM iterations, fraction kept) per round (8 -> 4 -> 3);
the rest run to convergence (at most ``max_iter`` iterations in all)."""
AGREE_REL = 1e-3  # two starts agree when their costs differ by less than this fraction [-]


@dataclass
class ShootingSearch:
    """The outcome of :func:`search` (SI).

    sp                    the multiple-shooting problem
    x, V, cost            the best start's parameters, scaled unknowns and data cost
    starts_x[m, p]        every start's initial parameters
    final_x[k, p]         the parameters of the starts that ran to the end, best first
    final_cost[k]         their costs
    agree                 how many of them reached the best cost (within AGREE_REL)
    iterations            LM iterations of the best start
    history               the best cost after each iteration
    timings               seconds per stage
    lengths, x_at         the lengths it was continued to, its parameters on each
    """

    sp: ShootingProblem
    x: np.ndarray
    V: np.ndarray
    cost: float
    starts_x: np.ndarray
    final_x: np.ndarray
    final_cost: np.ndarray
    agree: int
    iterations: int
    history: list[float]
    timings: dict[str, float]
    lengths: list[float] = field(default_factory=list)  # segment lengths continued to [s]
    final_V: np.ndarray | None = None  # scaled unknowns of the finishing starts, best first
    x_at: dict[float, np.ndarray] = field(default_factory=dict)
    """The parameters on the search's segments (key 0.0) and after each kept lengthening
    (key: the length [s]): two candidates are compared on the same segments."""


def sobol_starts(lower: np.ndarray, upper: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``n`` scrambled-Sobol points in the box [lower, upper] (SI), seeded."""
    from scipy.stats import qmc

    eng = qmc.Sobol(d=lower.shape[0], scramble=True, seed=np.random.default_rng(
        np.random.SeedSequence([seed, 0x73686F74])))
    u = eng.random(n)
    return lower + u * (upper - lower)


def build(problem: ClosedLoopProblem, segment_s: float, x_mid: np.ndarray, tie: bool = True
          ) -> ShootingProblem:
    """The multiple-shooting problem of ``problem`` with segments of about ``segment_s`` [s];
    the state scales from a reconstruction of the whole log at parameters ``x_mid``; ``tie``:
    the motor-angle tie (:meth:`ShootingProblem.tie_data`)."""
    from ema_cli.identify.closed_loop.shooting import make_segments, state_scales

    seg = make_segments(problem.log.t, segment_s)
    guess = reconstruct(problem, x_mid, np.arange(problem.log.n))
    return ShootingProblem(problem, seg, state_scales(problem, guess), tie=tie)


def search(problem: ClosedLoopProblem, *, n_starts: int, segment_s: float, dt: float,
           seed: int, max_iter: int, report: Any = None, tie: bool = True) -> ShootingSearch:
    """Multiple-shooting output-error search from ``n_starts`` Sobol starts over the bounds:
    segment states fitted per start, then batched joint LM with successive halving
    (:data:`HALVING`), the survivors run to convergence."""
    import time

    from ema_cli.identify.closed_loop.shooting_spread import lm_spread, start_states_spread

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    sp = build(problem, segment_s, 0.5 * (problem.lower + problem.upper), tie)
    X0 = sobol_starts(problem.lower, problem.upper, n_starts, seed)
    if report:
        report("segment states of every start", 0, 1)
    V0 = start_states_spread(sp, X0, dt)  # the starts in groups on the executor
    st = new_state(sp, V0, dt)
    timings["start_states_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    history: list[float] = []
    used = 0
    rounds = [*HALVING, (max_iter, 0.0)]
    alive = np.arange(n_starts)
    for k, (iters, keep) in enumerate(rounds):
        iters = min(iters, max_iter - used)
        if iters <= 0:
            break
        offset = used

        def prog(it: int, total: int, best: float, k: int = k, offset: int = offset) -> None:
            history.append(best)
            if report:
                report(f"joint fit, round {k + 1} of {len(rounds)} (J = {best:.6g})",
                       offset + it, max_iter)

        lm_spread(lm_many, sp, st, dt, iters, prog)
        used += iters
        if keep > 0.0 and k < len(rounds) - 1:
            n_keep = max(2, int(round(keep * alive.size)))
            alive = alive[np.argsort(st.cost[alive])][:n_keep]
            st.active[:] = False
            st.active[alive] = True  # a start that stalled may move again after a re-seat
            st.reseated[alive] = False
        if not np.any(st.active):
            break
    timings["joint_lm_s"] = time.perf_counter() - t0
    finished = alive[np.argsort(st.cost[alive])]
    best = int(finished[0])
    xs = np.array([sp.unpack(st.V[i])[0] for i in finished])
    costs = st.cost[finished]
    agree = int(np.sum(costs <= costs[0] * (1.0 + AGREE_REL)))
    x_best = xs[0]
    return ShootingSearch(sp, x_best, st.V[best].copy(), float(st.cost[best]), X0, xs,
                          costs, agree, int(st.iterations[best]), history, timings,
                          final_V=st.V[finished].copy())

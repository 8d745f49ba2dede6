"""The search of the multiple-shooting fit (:mod:`ema_cli.identify.shooting`): segment states
reconstructed from the measured channels and fitted per segment, then Levenberg-Marquardt on
the free parameters and every segment state together, many starts at once (one kernel call per
Jacobian and per round of trial steps), with successive halving of the starts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.identify.closed_loop import ClosedLoopProblem
from ema_cli.identify.shooting import (
    FAILED,
    N_X,
    NV,
    STATE_FD_REL,
    VAR_STATES,
    ShootingProblem,
    steady_z,
)
from ema_cli.model.params import to_row

LM_LAMBDA0 = 1e-3  # initial Levenberg-Marquardt damping of the per-segment state fits [-]
GAP_STARTS = (-1.0, -0.5, 0.0, 0.5, 1.0)  # starting gap positions q of a state fit [-]
LOCAL_FIT_HALF = 5  # samples each side of the local quadratic fits of a reconstruction [-]


def _local_fit(t: np.ndarray, y: np.ndarray, at: np.ndarray, half: int = LOCAL_FIT_HALF
               ) -> tuple[np.ndarray, np.ndarray]:
    """Value and slope of ``y(t)`` at sample indices ``at`` by local quadratic least squares
    over ``2*half + 1`` samples (fewer at the log's ends): smooths the noise of one sample."""
    val = np.empty(at.shape[0])
    slope = np.empty(at.shape[0])
    n = t.shape[0]
    for q, i in enumerate(at):
        a, b = max(0, int(i) - half), min(n, int(i) + half + 1)
        tt = t[a:b] - t[i]
        deg = min(2, b - a - 1)
        c = np.polyfit(tt, y[a:b], deg)
        val[q] = c[-1]
        slope[q] = c[-2] if deg >= 1 else 0.0
    return val, slope


def reconstruct(problem: ClosedLoopProblem, x: np.ndarray, at: np.ndarray,
                alt_load_speed: bool = False) -> np.ndarray:
    """Initial-state guesses [len(at), N_X] (SI) at log samples ``at`` from the measured
    channels and the controller's equations, for free parameters ``x``:

    theta_L, w_L   local quadratic fit of the measured load angle (value, slope); with
                   ``alt_load_speed`` and a logged motor speed, w_L = w_m/m (cleaner than the
                   slope in contact, wrong in the gap: both serve as starts)
    w_m, i         measured (local fit) when logged, else m*w_L and 0
    theta_m        m*theta_L (the middle of the gap)
    z              the LuGre steady state at w_m
    xI             the speed PI's integral of its error as computed from the logged command and
                   channels (position loop, sat1), from rest at the log's start
    """
    lg = problem.log
    prm = problem.params(x)
    m = prm["m"]
    t = lg.t
    thl = lg.channels["theta_load_deg"]
    thl_v, wl_v = _local_fit(t, thl, at)
    if "omega_motor_rpm" in lg.channels:
        wm_v, _ = _local_fit(t, lg.channels["omega_motor_rpm"], at)
        wm_all = lg.channels["omega_motor_rpm"]
        if alt_load_speed:
            wl_v = wm_v / m  # the gear's rate: cleaner than the load angle's slope in contact
    else:
        wm_v = m * wl_v
        wm_all = m * np.gradient(thl, t)
    if "current_a" in lg.channels:
        i_v, _ = _local_fit(t, lg.channels["current_a"], at)
    else:
        i_v = np.zeros(at.shape[0])
    q_v = np.zeros(at.shape[0])  # the middle of the gap
    z_v = steady_z(prm, wm_v)
    e_th = lg.theta_ref - thl
    w_ref = np.clip(prm["Kpp"] * e_th, -prm["sat1"], prm["sat1"]) * m
    e_w = w_ref - wm_all
    xi_all = np.concatenate([[0.0], np.cumsum(0.5 * (e_w[1:] + e_w[:-1]) * np.diff(t))])
    xi_v = xi_all[at]
    return np.column_stack([q_v, wm_v, i_v, thl_v, wl_v, z_v, xi_v])


def _data_index(sp: ShootingProblem) -> tuple[np.ndarray, np.ndarray]:
    """Per segment the global sample index of its data residuals (padded) and a mask."""
    key = "data_index"
    if key not in sp._plans:
        ranges = [sp.seg.data_range(k, sp.base.log.n) for k in range(sp.seg.n)]
        L = max(len(r) for r in ranges)
        idx = np.array([np.pad(np.arange(r.start, r.stop), (0, L - len(r)), mode="edge")
                        for r in ranges])
        mask = np.array([np.arange(L) < len(r) for r in ranges])
        sp._plans[key] = (idx, mask)
    return sp._plans[key]


def fit_states(sp: ShootingProblem, X: np.ndarray, S0: np.ndarray, group: np.ndarray,
               dt: float, iterations: int, prune_after: int = 6
               ) -> tuple[np.ndarray, np.ndarray]:
    """The initial state of every segment fitted to its own data for fixed parameters:
    instances ``X[K, p]`` (SI) with starting states ``S0[K, n_seg, NV]``, grouped by
    ``group[K]`` (0..G-1) -> per group and segment the best instance's fit (S [G, n_seg, NV]
    SI, data cost [G, n_seg]). Levenberg-Marquardt with one damping per (instance, segment);
    every instance in the same kernel calls (one for the forward-difference Jacobian, one for
    the trial step, per iteration); after ``prune_after`` iterations only the best instance of
    each (group, segment) goes on."""
    K, n = S0.shape[0], S0.shape[1]
    G = int(group.max()) + 1
    prms = [sp.base.params(x) for x in X]
    idx, mask = _data_index(sp)
    meas = sp.base.measured  # [n_ch, N]
    scales = sp.base.scales
    sig_v = sp.sigma[list(VAR_STATES)]
    inst = np.repeat(np.arange(K), n)  # instance of each (instance, segment) lane
    seg_of = np.tile(np.arange(n), K)
    L = idx.shape[1]

    def res(Sflat: np.ndarray, inst_of: np.ndarray, seg_of_: np.ndarray, reps: int
            ) -> np.ndarray:
        """Residuals [reps*lanes, n_ch, L] of reps blocks of lane states."""
        lanes = inst_of.shape[0]
        rows = np.empty((reps * lanes, len(to_row(prms[0]))))
        for q in range(reps):
            blk = Sflat[q * lanes:(q + 1) * lanes]
            for k in np.unique(inst_of):
                sel = inst_of == k
                rows[q * lanes + np.flatnonzero(sel)] = sp._rows(X[k], blk[sel], prms[k])
        Y, _, div = sp.simulate(rows, np.tile(seg_of_, reps), dt)
        Mi = meas[:, idx[seg_of_]].transpose(1, 0, 2)
        w = mask[seg_of_][:, None, :] / scales[None, :, None]
        R = (np.tile(Mi, (reps, 1, 1)) - Y[:, :, :L]) * np.tile(w, (reps, 1, 1))
        R[div] = FAILED
        return np.where(np.isfinite(R), R, FAILED)

    S = S0.reshape(K * n, NV).copy()
    lam = np.full(K * n, LM_LAMBDA0)
    cost = np.sum(res(S, inst, seg_of, 1) ** 2, axis=(1, 2))
    h = STATE_FD_REL * sig_v
    pruned = False
    for it in range(iterations):
        if not pruned and it == prune_after:
            S, cost, lam, inst, seg_of = _prune(S, cost, lam, inst, seg_of, group, G, n)
            pruned = True
        blocks = [S] + [S + h[s] * np.eye(NV)[s][None, :] for s in range(NV)]
        R = res(np.concatenate(blocks), inst, seg_of, NV + 1).reshape(NV + 1, S.shape[0], -1)
        r0 = R[0]
        Jb = ((R[1:] - r0[None]) / h[:, None, None]).transpose(1, 2, 0)  # [lanes, m, NV]
        A = np.einsum("imk,iml->ikl", Jb, Jb)
        g = np.einsum("imk,im->ik", Jb, r0)
        d = np.einsum("ikk->ik", A).copy()
        d[d <= 0] = 1.0
        Ad = A + lam[:, None, None] * (d[:, :, None] * np.eye(NV)[None])
        try:
            step = -np.linalg.solve(Ad, g[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            step = np.zeros_like(S)
        step = np.where(np.isfinite(step), step, 0.0)
        trial = S + step
        new = np.sum(res(trial, inst, seg_of, 1) ** 2, axis=(1, 2))
        better = new < cost
        S[better] = trial[better]
        cost = np.where(better, new, cost)
        lam = np.clip(np.where(better, lam / 3.0, lam * 4.0), 1e-9, 1e9)
    if not pruned:
        S, cost, lam, inst, seg_of = _prune(S, cost, lam, inst, seg_of, group, G, n)
    # after pruning: lane g*n + k is group g, segment k
    return S.reshape(G, n, NV), cost.reshape(G, n)


def _prune(S: np.ndarray, cost: np.ndarray, lam: np.ndarray, inst: np.ndarray,
           seg_of: np.ndarray, group: np.ndarray, G: int, n: int) -> tuple[np.ndarray, ...]:
    """Keep the best lane of each (group, segment), ordered group-major."""
    keep = np.empty(G * n, dtype=np.int64)
    gl = group[inst]
    for g in range(G):
        for k in range(n):
            lanes = np.flatnonzero((gl == g) & (seg_of == k))
            keep[g * n + k] = lanes[np.argmin(cost[lanes])]
    # each kept lane keeps its own instance's parameters
    return S[keep], cost[keep], lam[keep], inst[keep], seg_of[keep]


def state_starts(sp: ShootingProblem, x: np.ndarray, recs: list[np.ndarray]) -> np.ndarray:
    """Starting states [K, n_seg, NV] for :func:`fit_states`: every reconstruction in ``recs``
    ([n_seg, N_X] each) with the motor angle moved across the gap (:data:`GAP_STARTS` x
    alpha)."""
    out = []
    for S in recs:
        base = S[:, list(VAR_STATES)] if S.shape[1] == N_X else S
        for f in GAP_STARTS:
            b = base.copy()
            b[:, 0] += f
            out.append(b)
    return np.array(out)




RESEAT_RATIO = 1.5  # re-seat the segments whose cost exceeds this x the median segment's [-]
LM_TRIES = 8  # damping increases per LM iteration before a start is declared converged
LM_UP, LM_DOWN = 10.0, 5.0  # damping factors after a rejected / accepted step [-]
GN_LAMBDA = 1e-3  # a step with at most this Marquardt damping is nearly Gauss-Newton [-]
CHI2_TOL = 0.01
"""A start has converged when a nearly Gauss-Newton step lowers its cost by less than this
many residuals' worth (chi-square units at the noise level) [-]."""


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


def seg_costs(sp: ShootingProblem, R: np.ndarray) -> np.ndarray:
    """Data cost of every segment of candidates with residuals ``R[m, nd]`` -> [m, n_seg]."""
    owner, _ = sp._gather()
    n_ch, N = len(sp.base.channels), sp.base.log.n
    sq = np.sum(R.reshape(R.shape[0], n_ch, N) ** 2, axis=1)
    return np.stack([np.bincount(owner, weights=q, minlength=sp.seg.n) for q in sq])


def reseat(sp: ShootingProblem, st: LMState, dt: float, which: np.ndarray,
           iterations: int = 6, ratio: float = RESEAT_RATIO) -> None:
    """Re-fit every segment state of the starts ``which`` from starts across the gap (for
    their current parameters) and keep each segment's new state where it fits better."""
    if which.size == 0:
        return
    c1 = seg_costs(sp, st.R[which])
    # only the segments that fit clearly worse than the start's typical segment
    suspect = c1 > ratio * np.median(c1, axis=1, keepdims=True)
    which = which[np.any(suspect, axis=1)]
    c1 = c1[np.any(suspect, axis=1)]
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
                        prune_after=3)
    for g, i in enumerate(which):
        better = c2[g] < c1[g] * (1.0 - 1e-9)
        if np.any(better):
            x, S = sp.unpack(st.V[i])
            S[better] = S2[g][better]
            st.V[i] = sp.pack(x, S)
    R, _ = sp.residuals_many(st.V[which], dt)
    st.R[which] = R
    st.cost[which] = np.sum(R**2, axis=1)


def lm_many(sp: ShootingProblem, st: LMState, dt: float, max_iter: int,
            reseat_every: int = 5, tol: float = 1e-9, chi2_tol: float = CHI2_TOL,
            progress: Any = None) -> LMState:
    """Levenberg-Marquardt on the free parameters and every segment state together, for all
    active starts at once: per iteration ONE kernel call for all their Jacobians and one per
    round of trial steps (each start with its own damping, Marquardt's diagonal scaling;
    parameters clipped to their bounds). Every ``reseat_every`` iterations the segment
    states are re-seated (:func:`reseat`). A start stops when no damping lowers its cost or
    its relative decrease is below ``tol``, or when a nearly Gauss-Newton step (damping at
    most :data:`GN_LAMBDA`) lowers it by less than ``chi2_tol`` residuals' worth (``chi2_tol
    * cost / n_residuals``: with residuals at the noise level, ``chi2_tol`` in chi-square
    units, a tenth of a standard error from the optimum of the local quadratic model)."""
    p = sp.p
    n_res = max(sp.base.measured.size, 1)
    lo = np.concatenate([np.zeros(p), np.full(sp.n_vars - p, -np.inf)])
    hi = np.concatenate([np.ones(p), np.full(sp.n_vars - p, np.inf)])
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
        R0, Jx, Js = sp.jacobian_many(st.V[act], dt)
        AG = [sp.normal_equations(R0[q], Jx[q], Js[q]) for q in range(act.size)]
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
                    dv = -np.linalg.solve(A[q] + st.lam[i] * np.diag(d[q]), g[q])
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
                    st.V[i], st.R[i], st.cost[i] = trials[k], Rt[k], ct[k]
                    st.lam[i] = max(st.lam[i] / LM_DOWN, 1e-12)
                    if rel < tol or (lam_was <= GN_LAMBDA and rel * n_res < chi2_tol):
                        st.active[i] = False
                else:
                    st.lam[i] *= LM_UP
                    still.append(q)
            pending = still
        if pending:  # no damping lowered the cost: re-seat every segment state once first
            stuck = act[np.array(pending)]
            fresh = stuck[~st.reseated[stuck]]
            before = st.cost[fresh].copy()
            reseat(sp, st, dt, fresh, ratio=0.0)
            if fresh.size:
                st.V[fresh], st.R[fresh], st.cost[fresh] = chain_seat(sp, st.V[fresh], dt)
            st.reseated[fresh] = True
            for i, c in zip(fresh, before, strict=True):
                if st.cost[i] < c * (1.0 - 1e-6):
                    st.lam[i] = 1e-3
                    st.reseated[i] = False  # moved: may re-seat again when stuck again
                else:
                    st.active[i] = False
            st.active[stuck[st.reseated[stuck] & ~np.isin(stuck, fresh)]] = False
        st.iterations[act] += 1
        st.history.append(st.cost.copy())
        if progress is not None:
            progress(it, max_iter, float(np.min(st.cost)))
    return st


def start_states(sp: ShootingProblem, X: np.ndarray, dt: float, iterations: int = 12
                 ) -> np.ndarray:
    """Segment states fitted for each parameter start ``X[m, p]`` from its reconstructions
    and starts across the gap (:func:`fit_states`, all starts batched) -> V[m, n_vars]."""
    at = sp.seg.first
    Xi, starts, group = [], [], []
    for g, x in enumerate(X):
        recs = [reconstruct(sp.base, x, at), reconstruct(sp.base, x, at, alt_load_speed=True)]
        for S0 in state_starts(sp, x, recs):
            Xi.append(x)
            starts.append(S0)
            group.append(g)
    S, _ = fit_states(sp, np.array(Xi), np.array(starts), np.array(group), dt, iterations)
    V = np.array([sp.pack(x, S[g]) for g, x in enumerate(X)])
    return chain_seat(sp, V, dt)[0]


CHAIN_SWEEPS = 8  # most sweeps of :func:`chain_seat`


def chain_seat(sp: ShootingProblem, V: np.ndarray, dt: float, sweeps: int = CHAIN_SWEEPS
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Seat each segment at the end of the previous one where that fits its data better:
    candidates ``V[m, n_vars]`` (scaled) -> (V, residuals R[m, nd], data costs [m]).

    A segment whose own state fit fell into a wrong local minimum (e.g. the wrong side of the
    gap while the load coasts) is re-started from the state its predecessor's simulation
    reaches; one kernel call per sweep for every candidate and segment, repeated while any
    segment improves, so a good start propagates along the log."""
    V = V.copy()
    R, ends = sp.residuals_many(V, dt)
    c = seg_costs(sp, R)
    # the first segment from rest (a log that starts with the actuator at rest, as a test
    # log does): every state 0, the load angle 0 or its measured value
    th0, _ = _local_fit(sp.base.log.t, sp.base.log.channels["theta_load_deg"], np.array([0]))
    for th in {0.0, float(th0[0])}:
        W = V.copy()
        for i in range(V.shape[0]):
            x, S = sp.unpack(V[i])
            S[0] = 0.0
            S[0, 3] = th
            W[i] = sp.pack(x, S)
        R2, ends2 = sp.residuals_many(W, dt)
        c2 = seg_costs(sp, R2)
        for i in np.flatnonzero(c2[:, 0] < c[:, 0]):
            x, S = sp.unpack(V[i])
            S[0] = sp.unpack(W[i])[1][0]
            V[i] = sp.pack(x, S)
    R, ends = sp.residuals_many(V, dt)
    c = seg_costs(sp, R)
    for _ in range(sweeps):
        W = V.copy()
        for i in range(V.shape[0]):
            x, S = sp.unpack(V[i])
            S2 = S.copy()
            S2[1:] = ends[i, :-1]  # q, w_m, i, theta_L, w_L, xI (VAR_STATES order)
            W[i] = sp.pack(x, S2)
        R2, ends2 = sp.residuals_many(W, dt)
        c2 = seg_costs(sp, R2)
        better = c2 < c * (1.0 - 1e-9)
        better[:, 0] = False
        if not np.any(better):
            break
        for i in range(V.shape[0]):
            if np.any(better[i]):
                x, S = sp.unpack(V[i])
                _, S2 = sp.unpack(W[i])
                S[better[i]] = S2[better[i]]
                V[i] = sp.pack(x, S)
        R, ends = sp.residuals_many(V, dt)
        c = seg_costs(sp, R)
    return V, R, np.sum(R**2, axis=1)


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


def sobol_starts(lower: np.ndarray, upper: np.ndarray, n: int, seed: int) -> np.ndarray:
    """``n`` scrambled-Sobol points in the box [lower, upper] (SI), seeded."""
    from scipy.stats import qmc

    eng = qmc.Sobol(d=lower.shape[0], scramble=True, seed=np.random.default_rng(
        np.random.SeedSequence([seed, 0x73686F74])))
    u = eng.random(n)
    return lower + u * (upper - lower)


def build(problem: ClosedLoopProblem, segment_s: float, x_mid: np.ndarray) -> ShootingProblem:
    """The multiple-shooting problem of ``problem`` with segments of about ``segment_s`` [s];
    the state scales from a reconstruction of the whole log at parameters ``x_mid``."""
    from ema_cli.identify.shooting import make_segments, state_scales

    seg = make_segments(problem.log.t, segment_s)
    guess = reconstruct(problem, x_mid, np.arange(problem.log.n))
    return ShootingProblem(problem, seg, state_scales(problem, guess))


def search(problem: ClosedLoopProblem, *, n_starts: int, segment_s: float, dt: float,
           seed: int, max_iter: int, report: Any = None) -> ShootingSearch:
    """Multiple-shooting output-error search from ``n_starts`` Sobol starts over the bounds:
    segment states fitted per start, then batched joint LM with successive halving
    (:data:`HALVING`), the survivors run to convergence."""
    import time

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    sp = build(problem, segment_s, 0.5 * (problem.lower + problem.upper))
    X0 = sobol_starts(problem.lower, problem.upper, n_starts, seed)
    if report:
        report("segment states of every start", 0, 1)
    V0 = start_states(sp, X0, dt)
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

        lm_many(sp, st, dt, iters, progress=prog)
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

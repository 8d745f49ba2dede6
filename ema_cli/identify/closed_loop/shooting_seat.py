"""Seating the segment states of the multiple-shooting fit
(:mod:`ema_cli.identify.closed_loop.shooting`):
states reconstructed from the measured channels (local fits of the logged signals), fitted
segment by segment (batched Levenberg-Marquardt on the states alone, from starts across the
gap), and chained (each segment restarted from its predecessor's simulated end where that fits
its data better, the first from rest).
"""

from __future__ import annotations

import numpy as np

from ema_cli.identify.closed_loop.problem import ClosedLoopProblem
from ema_cli.identify.closed_loop.shooting import (
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
PRUNE_AFTER = 1
"""State-fit iterations of every start across the gap before only the best goes on [-]. Each
of the ten starts of a segment costs 1 + NV kernel lanes per iteration, so at 3 (until this
release) the first iterations were 77 % of the start states' kernel work; measured on the
README's example, pruning after 1 left the eight starts' seated costs J/N 0.27 to 3.4 (after
3: 0.27 to 1040) for 52 % of the work (1.12e8 lane-steps against 2.15e8)."""
STATE_CHI2 = 0.01
"""A lane of :func:`fit_states` (a segment's state from one start) has converged when a step
lowers its cost by less than this many residuals' worth at its noise level [-]: it is no
longer simulated (each lane's fit is its own, so the others are the same bits)."""


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
               dt: float, iterations: int, prune_after: int = 6,
               which: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The initial state of every segment fitted to its own data for fixed parameters:
    instances ``X[K, p]`` (SI) with starting states ``S0[K, n_seg, NV]``, grouped by
    ``group[K]`` (0..G-1) -> per group and segment the best instance's fit (S [G, n_seg, NV]
    SI, data cost [G, n_seg]). Levenberg-Marquardt with one damping per (instance, segment);
    every instance in the same kernel calls (one for the forward-difference Jacobian, one for
    the trial step, per iteration); after ``prune_after`` iterations only the best instance of
    each (group, segment) goes on, and a lane that has converged (:data:`STATE_CHI2`) is no
    longer simulated. ``which[G, n_seg]`` (bool) fits only those segments of
    each group: the others are returned as the group's first start with cost inf (a segment
    fits alone, so the fitted ones are the same as in a fit of all)."""
    n = S0.shape[1]
    G = int(group.max()) + 1
    if which is None:
        which = np.ones((G, n), dtype=bool)
    prms = [sp.base.params(x) for x in X]
    idx, mask = _data_index(sp)
    meas = sp.base.measured  # [n_ch, N]
    scales = sp.base.scales
    sig_v = sp.sigma[list(VAR_STATES)]
    # the (instance, segment) lanes: every instance on its group's chosen segments
    lane_k, lane_s = np.nonzero(which[group])
    inst, seg_of = lane_k, lane_s
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

    S = S0[inst, seg_of].copy()
    lam = np.full(inst.shape[0], LM_LAMBDA0)
    cost = np.sum(res(S, inst, seg_of, 1) ** 2, axis=(1, 2))
    live = np.ones(inst.shape[0], dtype=bool)  # the lanes still moving
    n_res = len(sp.base.channels) * np.sum(mask, axis=1)  # data residuals per segment
    h = STATE_FD_REL * sig_v
    pruned = False
    for it in range(iterations):
        if not pruned and it == prune_after:
            S, cost, lam, inst, seg_of, live = _prune(S, cost, lam, inst, seg_of, group, G, n,
                                                      live)
            pruned = True
        on = np.flatnonzero(live)
        if on.size == 0:
            continue
        Sa = S[on]
        blocks = [Sa] + [Sa + h[s] * np.eye(NV)[s][None, :] for s in range(NV)]
        R = res(np.concatenate(blocks), inst[on], seg_of[on], NV + 1).reshape(
            NV + 1, on.size, -1)
        r0 = R[0]
        Jb = ((R[1:] - r0[None]) / h[:, None, None]).transpose(1, 2, 0)  # [lanes, m, NV]
        A = np.einsum("imk,iml->ikl", Jb, Jb)
        g = np.einsum("imk,im->ik", Jb, r0)
        d = np.einsum("ikk->ik", A).copy()
        d[d <= 0] = 1.0
        Ad = A + lam[on][:, None, None] * (d[:, :, None] * np.eye(NV)[None])
        try:
            step = -np.linalg.solve(Ad, g[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            step = np.zeros_like(Sa)
        step = np.where(np.isfinite(step), step, 0.0)
        trial = Sa + step
        new = np.sum(res(trial, inst[on], seg_of[on], 1) ** 2, axis=(1, 2))
        better = new < cost[on]
        # a lane has converged when a step lowers its cost by less than STATE_CHI2
        # residuals' worth (at its own noise level): it is simulated no more
        done = better & (cost[on] - new < STATE_CHI2 * new / n_res[seg_of[on]])
        S[on[better]] = trial[better]
        cost[on] = np.where(better, new, cost[on])
        lam[on] = np.clip(np.where(better, lam[on] / 3.0, lam[on] * 4.0), 1e-9, 1e9)
        live[on[done]] = False
    if not pruned:
        S, cost, lam, inst, seg_of, live = _prune(S, cost, lam, inst, seg_of, group, G, n,
                                                  live)
    # after pruning: one lane per chosen (group, segment)
    first = np.array([np.flatnonzero(group == g)[0] for g in range(G)])
    S_out = S0[first].copy()
    c_out = np.full((G, n), np.inf)
    S_out[group[inst], seg_of] = S
    c_out[group[inst], seg_of] = cost
    return S_out, c_out


def _prune(S: np.ndarray, cost: np.ndarray, lam: np.ndarray, inst: np.ndarray,
           seg_of: np.ndarray, group: np.ndarray, G: int, n: int, live: np.ndarray
           ) -> tuple[np.ndarray, ...]:
    """Keep the best lane of each (group, segment) (the first such lane on a tie), ordered
    group-major."""
    key = group[inst] * n + seg_of
    order = np.lexsort((np.arange(key.shape[0]), cost, key))
    starts = np.r_[True, key[order][1:] != key[order][:-1]]
    keep = order[starts]
    # each kept lane keeps its own instance's parameters
    return S[keep], cost[keep], lam[keep], inst[keep], seg_of[keep], live[keep]


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


def seg_costs(sp: ShootingProblem, R: np.ndarray) -> np.ndarray:
    """Data cost of every segment of candidates with residuals ``R[m, nd]`` -> [m, n_seg]."""
    owner, _ = sp._gather()
    n_ch, N = len(sp.base.channels), sp.base.log.n
    sq = np.sum(R[:, :n_ch * N].reshape(R.shape[0], n_ch, N) ** 2, axis=1)
    return np.stack([np.bincount(owner, weights=q, minlength=sp.seg.n) for q in sq])


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
    S, _ = fit_states(sp, np.array(Xi), np.array(starts), np.array(group), dt, iterations,
                      prune_after=PRUNE_AFTER)
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

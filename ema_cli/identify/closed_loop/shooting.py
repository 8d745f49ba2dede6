"""Multiple shooting for the closed-loop fit: the log cut into short segments, each simulated
from an estimated initial state.

Why: with backlash, the load flies free in the gap and small differences in impact timing
grow; over a long log the output-error cost of single shooting is rugged and nearly chaotic
(docs/identification.md). Over a short horizon from a state on the measured trajectory the
cost is smooth and nearly unimodal in the parameters (Bock's multiple shooting; Ribeiro,
Tiels, Umenberger, Schon and Aguirre, "On the smoothness of nonlinear system identification",
Automatica 2020).

Unknowns (scaled): the free parameters ``u = (x - lo)/(hi - lo)`` in [0, 1] and, per segment
``k``, the initial state ``S_k = [q, w_m, i, theta_L, w_L, xI]`` over its scale ``sigma_s``
(:func:`state_scales`), where the motor angle is given by its position in the gap,
``q = (theta_m/m - theta_L)/(alpha + GAP_FLOOR)`` (|q| < 1: in the gap), so that a segment
stays at the same place in the gap, in contact or not, when alpha changes; z starts at its
steady state (:data:`VAR_STATES`). The residuals are the data's,
``(y_c,i - yhat_c,i(x, S_k)) / s_c``, every log sample once (owned by one segment). There are
no continuity residuals: the segments are joined only through their seating
(``shooting_search.chain_seat`` restarts a segment from its predecessor's simulated end state,
which :meth:`ShootingProblem.simulate` returns, where that fits better).

Every evaluation (a residual vector, a whole finite-difference Jacobian) is ONE batched kernel
call: rows = candidates x segments, each row following its own segment's command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.identify.closed_loop.problem import (
    CHANNELS,
    ON_GRID_TOL,
    OVERSAMPLE,
    ClosedLoopProblem,
    KernelWork,
)
from ema_cli.model.params import INDEX, to_row

SEGMENT_STATES = ("theta_m", "w_m", "i", "theta_L", "w_L", "z", "xI")
"""The states of a segment start (``model.states.STATES`` by name: the paper's EMA's, the
actuator this fit identifies); a segment's other states start at their initial values."""
N_X = len(SEGMENT_STATES)  # states per segment start
VAR_STATES = tuple(SEGMENT_STATES.index(n) for n in ("theta_m", "w_m", "i", "theta_L", "w_L",
                                                     "xI"))
"""The states estimated per segment (positions in :data:`SEGMENT_STATES`)."""
_X0 = {n: INDEX[f"x0_{n}"] for n in SEGMENT_STATES}  # their initial-state columns of P
GAP_FLOOR = 1e-5  # the gap position q is the deflection over (alpha + this) [rad]
Q_SCALE = 0.05  # the scale of the gap position q [-]
NV = len(VAR_STATES)
"""The bristle state z is not estimated: it forgets its initial value within milliseconds
(too weakly observable to estimate, and its estimate would wander outside |z| <= Fs/sigma0);
each segment starts it at the LuGre steady state of its motor speed."""
STATE_FD_REL = 1e-3  # finite-difference step of a state, in state scales [-]
PARAM_FD_REL = 1e-4  # finite-difference step of a parameter, relative (see fd steps) [-]
STATE_SCALE_FRACTION = 1e-2  # a state's scale: this fraction of its RMS over the log [-]
FAILED = 1e6  # residual of a diverged or non-finite simulation [-]
_SIG_OF_STATE = ("theta_motor", "omega_motor", "current", "theta_load", "omega_load",
                 "voltage_cmd", "theta_ref")
"""The recorded signals of the end states (theta_motor is theta_m/m); the last two give xI."""


@dataclass(frozen=True)
class Segments:
    """The log cut into segments: segment k starts at sample ``first[k]`` and ends at sample
    ``last[k]`` (= ``first[k+1]``; the last one at the log's end). Its data residuals are the
    samples ``first[k] .. last[k]-1`` (the last segment: ``.. last[k]``)."""

    first: np.ndarray
    last: np.ndarray

    @property
    def n(self) -> int:
        return int(self.first.shape[0])

    def data_range(self, k: int, n_samples: int) -> range:
        """The log samples whose residuals segment ``k`` owns."""
        end = self.last[k] + 1 if k == self.n - 1 else self.last[k]
        return range(int(self.first[k]), int(min(end, n_samples)))


def make_segments(t: np.ndarray, length_s: float, min_samples: int = 10) -> Segments:
    """Cut log times ``t`` [s] into segments of about ``length_s`` [s] (equal in samples where
    the log is uniform), each at least ``min_samples`` samples long."""
    n = t.shape[0]
    duration = float(t[-1] - t[0])
    n_seg = max(1, int(round(duration / length_s)))
    n_seg = min(n_seg, max(1, (n - 1) // min_samples))
    edges = np.searchsorted(t, t[0] + np.linspace(0.0, duration, n_seg + 1))
    edges[0], edges[-1] = 0, n - 1
    edges = np.unique(edges)
    return Segments(edges[:-1].copy(), edges[1:].copy())


@dataclass
class ShootingProblem:
    """The multiple-shooting residuals of a closed-loop problem (see the module docstring).

    base        the single-shooting problem: log, free set, bounds, fixed plant, channels,
                scales (its ``params`` maps a free vector to SI parameters)
    seg         the segments
    sigma       state scales [N_X] (SI)
    """

    base: ClosedLoopProblem
    seg: Segments
    sigma: np.ndarray
    tie: bool = False  # the motor-angle tie residuals (:meth:`tie_data`) when the log allows
    work: KernelWork = field(default_factory=KernelWork)  # the fit's, shared when derived
    _refs: dict = field(default_factory=dict, repr=False)
    _plans: dict = field(default_factory=dict, repr=False)

    @property
    def p(self) -> int:
        return len(self.base.names)

    @property
    def n_vars(self) -> int:
        return self.p + self.seg.n * NV

    @property
    def n_data(self) -> int:
        """Data residuals (every channel's every sample) ahead of the tie residuals."""
        return len(self.base.channels) * self.base.log.n

    # ---- the motor-angle tie ---------------------------------------------------------------
    def tie_data(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The motor-angle tie, or None (``tie`` off, no motor speed fitted, one segment).

        Only the motor *speed* is logged, so each segment's motor angle would be free; but
        the motor turns by the integral of its speed between two segment starts. The tie
        residuals are ``(dI_k - (theta_m0[k+1] - theta_m0[k])) / s_k`` (k = 0 .. n_seg-2),
        with ``dI_k`` the trapezoid integral of the logged motor speed from the start of
        segment k to the start of k+1 [rad, motor side] and ``s_k`` its standard error: the
        speed channel's scale through the trapezoid weights, with the quadrature error
        (Simpson's rule minus the trapezoid's) added in quadrature. They are kinematics, true
        under any contact law. -> (dI [n_seg-1], s [n_seg-1]) SI."""
        if "tie" in self._plans:
            return self._plans["tie"]
        out = None
        ch = list(self.base.channels)
        if self.tie and self.seg.n > 1 and "omega_motor_rpm" in ch:
            from scipy.integrate import simpson

            c = ch.index("omega_motor_rpm")
            w = self.base.measured[c]
            t = self.base.log.t
            s_w = float(self.base.scales[c])
            d_i, s_i = [], []
            for a, b in zip(self.seg.first[:-1], self.seg.first[1:], strict=True):
                tt, ww = t[a:b + 1], w[a:b + 1]
                h = np.diff(tt)
                wt = np.zeros(tt.shape[0])  # the trapezoid's weights
                wt[1:] += 0.5 * h
                wt[:-1] += 0.5 * h
                trap = float(wt @ ww)
                quad = float(simpson(ww, x=tt)) - trap if tt.shape[0] > 2 else 0.0
                d_i.append(trap)
                s_i.append(math.sqrt(s_w**2 * float(np.sum(wt**2)) + quad**2))
            out = (np.array(d_i), np.maximum(np.array(s_i), 1e-12))
        self._plans["tie"] = out
        return out

    def tie_residuals(self, rows: np.ndarray, m: int) -> np.ndarray:
        """Tie residuals ``[m, n_seg-1]`` of m candidates from their parameter rows
        (``m*n_seg``, candidate after candidate; the motor angle in its x0 column)."""
        d_i, s_i = self.tie_data()
        th = rows[:, _X0["theta_m"]].reshape(m, self.seg.n)
        return (d_i[None] - np.diff(th, axis=1)) / s_i[None]

    def tie_state_jacobian(self, v: np.ndarray) -> np.ndarray:
        """d(tie residuals)/d(scaled segment states) ``[n_seg-1, n_seg*NV]`` of candidate
        ``v`` (analytic: the motor angle ``m*(theta_L + q*(alpha + GAP_FLOOR))``)."""
        _, s_i = self.tie_data()
        n = self.seg.n
        prm = self.base.params(self.unpack(v)[0])
        d = np.zeros(NV)
        d[0] = prm["m"] * (prm["alpha"] + GAP_FLOOR) * self.sigma[VAR_STATES[0]]
        d[3] = prm["m"] * self.sigma[VAR_STATES[3]]
        T = np.zeros((n - 1, n * NV))
        for k in range(n - 1):
            T[k, k * NV:(k + 1) * NV] = d / s_i[k]
            T[k, (k + 1) * NV:(k + 2) * NV] = -d / s_i[k]
        return T

    # ---- the simulation of every segment ------------------------------------------------
    def _plan(self, dt: float) -> dict[str, Any]:
        """Steps, record decimation and sample indices of every segment at step ``dt``."""
        if dt in self._plans:
            return self._plans[dt]
        from ema_cli.sim.signals import InputSignal, Sampler

        lg = self.base.log
        t = lg.t
        rel = [t[a:b + 1] - t[a] for a, b in zip(self.seg.first, self.seg.last, strict=True)]
        longest = max(float(r[-1]) for r in rel)
        n_steps = int(math.ceil(longest / dt - ON_GRID_TOL))
        ks = [r / dt for r in rel]
        on = all(np.all(np.abs(k - np.round(k)) <= ON_GRID_TOL) for k in ks)
        if on:
            ki = [np.round(k).astype(np.int64) for k in ks]
            steps = np.concatenate([np.diff(k) for k in ki if k.shape[0] > 1])
            dec = max(int(np.gcd.reduce(steps)), 1)
            index = [k // dec for k in ki]
        else:
            h = float(np.median(np.diff(t)))
            dec = max(1, int(h / dt / OVERSAMPLE))
            index = None
        refs = []
        for a, b in zip(self.seg.first, self.seg.last, strict=True):
            hi = min(int(b) + 2, lg.n)  # one sample beyond the end for the interpolation
            tt, rr = self.base.command_table(int(a), hi - 1)
            tt = tt - t[a]
            if tt.shape[0] < 2:
                tt, rr = np.array([0.0, 1.0]), np.array([rr[0], rr[0]])
            sig = InputSignal("csv", table=(tuple(tt.tolist()), tuple(rr.tolist())),
                              path=lg.source)
            refs.append(Sampler(sig, dt, n_steps, memo=True))  # run hundreds of times
        L = max(r.shape[0] for r in rel)
        plan = {"n_steps": n_steps, "dec": dec, "index": index, "rel": rel, "refs": refs,
                "pad_rel": np.array([np.pad(r, (0, L - r.shape[0]), mode="edge") for r in rel])}
        if index is not None:
            plan["pad_index"] = np.array([np.pad(k, (0, L - k.shape[0]), mode="edge")
                                          for k in index])
            plan["end_index"] = np.array([k[-1] for k in index])
        self._plans[dt] = plan
        return plan

    def simulate(self, rows: np.ndarray, seg_of_row: np.ndarray, dt: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Run parameter rows (initial states in their x0 columns), row r following segment
        ``seg_of_row[r]``, in one kernel call at step ``dt`` -> (the simulated channels at the
        segment's samples ``Y[rows, n_ch, L]``, padded past a segment's end by its last value;
        end states ``[rows, NV]`` in VAR_STATES order (xI from the controller's law);
        diverged ``[rows]``)."""
        from ema_cli.sim.runner import simulate_batch
        from ema_cli.sim.tables import SIG

        plan = self._plan(dt)
        ch = [SIG[CHANNELS[c][0]] for c in self.base.channels]
        st = [SIG[s] for s in _SIG_OF_STATE]
        # only the first signals up to the last one read here are recorded (8 of the 17-21):
        # the kernel writes and the runner allocates less, the values are the same bits
        res = simulate_batch(rows, plan["refs"], seg_of_row, dt, plan["n_steps"], plan["dec"],
                             parallel=True, n_signals=max(ch + st) + 1)
        self.work.add(rows.shape[0], rows.shape[0] * plan["n_steps"], res.kernel_s)
        sig = res.signals
        if plan["index"] is not None:
            idx = plan["pad_index"][seg_of_row]  # [rows, L]
            r_ = np.arange(rows.shape[0])[:, None]
            # gather only the channels, not every recorded signal, channel by channel into
            # [n_ch, rows, L] seen as [rows, n_ch, L]: the memory layout numpy gave the former
            # sig[r_, idx][:, :, ch], so every later sum adds in the same order (bit-identical)
            Yc = np.empty((len(ch), rows.shape[0], idx.shape[1]))
            for q, c in enumerate(ch):
                Yc[q] = sig[r_, idx, c]
            Y = Yc.transpose(1, 0, 2)
            ends = sig[np.arange(rows.shape[0])[:, None], plan["end_index"][seg_of_row][:, None],
                       np.array(st)[None, :]]
        else:
            L = plan["pad_rel"].shape[1]
            Y = np.empty((rows.shape[0], len(ch), L))
            ends = np.empty((rows.shape[0], len(st)))
            for r in range(rows.shape[0]):
                tr = plan["pad_rel"][seg_of_row[r]]
                for q, s in enumerate(ch):
                    Y[r, q] = np.interp(tr, res.t_out, sig[r, :, s])
                te = plan["rel"][seg_of_row[r]][-1]
                for q, s in enumerate(st):
                    ends[r, q] = np.interp(te, res.t_out, sig[r, :, s])
        ends = np.array(ends, dtype=np.float64)
        # the motor angle as its position in the gap (theta_motor is theta_m/m)
        ends[:, 0] = (ends[:, 0] - ends[:, 3]) / (rows[:, INDEX["alpha"]] + GAP_FLOOR)
        # the speed-PI integral from the controller's law, u = Kps*e_w + Kis*xI (exact while
        # SAT2 is inactive and the sensors are ideal; a starting guess otherwise)
        col = {k: rows[:, INDEX[k]] for k in ("Kpp", "Kps", "Kis", "m", "sat1")}
        w_ref = col["m"] * np.clip(col["Kpp"] * (ends[:, 6] - ends[:, 3]), -col["sat1"],
                                   col["sat1"])
        e_w = w_ref - ends[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            ends[:, 5] = np.where(col["Kis"] > 0, (ends[:, 5] - col["Kps"] * e_w) / col["Kis"],
                                  0.0)
        ends = ends[:, :6]
        return Y, ends, res.diverged

    # ---- residuals and Jacobian ----------------------------------------------------------
    def unpack(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Scaled unknowns -> (free parameters x [p] SI, estimated states S [n_seg, NV] SI)."""
        b = self.base
        x = b.lower + v[:self.p] * (b.upper - b.lower)
        S = v[self.p:].reshape(self.seg.n, NV) * self.sigma[None, list(VAR_STATES)]
        return x, S

    def pack(self, x: np.ndarray, S: np.ndarray) -> np.ndarray:
        """(x [p] SI, states [n_seg, N_X or NV] SI) -> scaled unknowns."""
        b = self.base
        u = (x - b.lower) / (b.upper - b.lower)
        if S.shape[1] == N_X:
            S = S[:, list(VAR_STATES)]
        return np.concatenate([u, (S / self.sigma[None, list(VAR_STATES)]).ravel()])

    def _rows(self, x: np.ndarray, S: np.ndarray, prm: dict | None = None) -> np.ndarray:
        """Parameter rows of every segment: free parameters ``x``, initial states ``S``
        [n_seg, NV] and z at the LuGre steady state of each segment's motor speed."""
        prm = self.base.params(x) if prm is None else prm
        base = np.array(to_row(prm))
        rows = np.repeat(base[None], S.shape[0], axis=0)
        rows[:, [_X0[SEGMENT_STATES[k]] for k in VAR_STATES]] = S
        rows[:, _X0["theta_m"]] = prm["m"] * (S[:, 3] + S[:, 0] * (prm["alpha"] + GAP_FLOOR))
        rows[:, _X0["z"]] = steady_z(prm, S[:, 1])
        return rows

    def _gather(self) -> tuple[np.ndarray, np.ndarray]:
        """(owner segment, index within it) of every log sample."""
        if "gather" not in self._plans:
            N = self.base.log.n
            owner = np.empty(N, dtype=np.int64)
            local = np.empty(N, dtype=np.int64)
            for k in range(self.seg.n):
                rng = self.seg.data_range(k, N)
                owner[rng.start:rng.stop] = k
                local[rng.start:rng.stop] = np.arange(len(rng))
            self._plans["gather"] = (owner, local)
        return self._plans["gather"]

    def _data_residuals(self, Y: np.ndarray) -> np.ndarray:
        """Weighted data residuals [n_cand, n_ch, N] of candidates whose segment predictions
        are ``Y[n_cand*n_seg, n_ch, L]`` (candidate after candidate)."""
        b = self.base
        owner, local = self._gather()
        n = self.seg.n
        Yc = Y.reshape(-1, n, Y.shape[1], Y.shape[2])
        G = Yc[:, owner, :, local]  # [N, n_cand, n_ch] (advanced indices first)
        G = G.transpose(1, 2, 0)
        return (b.measured[None] - G) / b.scales[None, :, None]

    def rows_many(self, V: np.ndarray) -> np.ndarray:
        """Parameter rows of candidates ``V[m, n_vars]`` (scaled): m*n_seg rows, candidate
        after candidate (each its segments in order)."""
        out = []
        prms: dict[bytes, dict] = {}
        for v in V:
            x, S = self.unpack(v)
            key = x.tobytes()
            if key not in prms:
                prms[key] = self.base.params(x)
            out.append(self._rows(x, S, prms[key]))
        return np.concatenate(out)

    def residuals_many(self, V: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Weighted data residuals ``R[m, n_ch*N]`` (channel after channel; then the tie
        residuals, :meth:`tie_data`, where there are some) of candidates
        ``V[m, n_vars]`` in one kernel call, and their end states ``[m, n_seg, 5]`` (SI, the
        motor angle as gap position). A candidate with a diverged segment gets
        :data:`FAILED` everywhere."""
        m, n = V.shape[0], self.seg.n
        rows = self.rows_many(V)
        Y, ends, div = self.simulate(rows, np.tile(np.arange(n), m), dt)
        R = self._data_residuals(Y).reshape(m, -1)
        if self.tie_data() is not None:
            R = np.concatenate([R, self.tie_residuals(rows, m)], axis=1)
        bad = np.any(div.reshape(m, n), axis=1) | ~np.all(np.isfinite(R), axis=1)
        R[bad] = FAILED
        return R, ends.reshape(m, n, -1)

    def jacobian_many(self, V: np.ndarray, dt: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals ``R[m, nd]`` and compact forward-difference Jacobians of candidates
        ``V[m, n_vars]``, everything in ONE kernel call: per candidate its base point, one
        perturbation per parameter (``Jx[m, nd, p]``) and one per state, applied to every
        segment at once (``Js[m, nd, NV]``: each data residual's derivative by the states of
        the segment that owns it, the only states it depends on; the tie residuals' rows of
        ``Js`` are meaningless: their state derivatives are :meth:`tie_state_jacobian`)."""
        p, ns = self.p, NV
        m = V.shape[0]
        b = self.base
        span = b.upper - b.lower
        blocks = []
        hu = np.empty((m, p))
        for i, v in enumerate(V):
            x = b.lower + v[:p] * span
            hu[i] = PARAM_FD_REL * np.maximum(np.abs(x), 1e-3 * span) / span
            blocks.append(v)
            for j in range(p):
                w = v.copy()
                # step away from the nearer bound
                w[j] = v[j] + hu[i, j] if v[j] + hu[i, j] <= 1.0 else v[j] - hu[i, j]
                blocks.append(w)
            for s in range(ns):
                w = v.copy()
                w[p + s::ns] += STATE_FD_REL
                blocks.append(w)
        R, _ = self.residuals_many(np.array(blocks), dt)
        R = R.reshape(m, 1 + p + ns, -1)
        r0 = R[:, 0]
        hx = np.array([[blocks[i * (1 + p + ns) + 1 + j][j] - V[i, j] for j in range(p)]
                       for i in range(m)]).reshape(m, p)
        Jx = (R[:, 1:1 + p] - r0[:, None]) / hx[:, :, None]  # [m, p, nd]
        Js = (R[:, 1 + p:] - r0[:, None]) / STATE_FD_REL  # [m, NV, nd] (owner's state)
        return r0, Jx.transpose(0, 2, 1), Js.transpose(0, 2, 1)

    def normal_equations(self, r: np.ndarray, Jx: np.ndarray, Js: np.ndarray,
                         v: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``A = J^T J`` and ``g = J^T r`` of candidate ``v`` from its compact Jacobian
        (``Jx[nd, p]``; ``Js[nd, NV]``, each data row's derivative by its own segment's
        states): the data's state blocks are block-diagonal, assembled per segment; the tie
        residuals (if any; ``v`` needed) couple neighbouring segments."""
        p, n = self.p, self.seg.n
        nd = self.n_data
        A = np.zeros((self.n_vars, self.n_vars))
        g = np.zeros(self.n_vars)
        A[:p, :p] = Jx.T @ Jx
        g[:p] = Jx.T @ r
        # the sums over each segment's samples (a run in order, every channel) at once
        n_ch, N = len(self.base.channels), self.base.log.n
        jsd, rd = Js[:nd].reshape(n_ch, N, NV), r[:nd].reshape(n_ch, N)
        at = self.seg.first  # the first sample each segment owns (Segments.data_range)
        Ass = np.add.reduceat(np.einsum("cik,cil->ikl", jsd, jsd), at, axis=0)
        Aps = np.add.reduceat(np.einsum("cij,cik->ijk", Jx[:nd].reshape(n_ch, N, p), jsd), at,
                              axis=0)
        g[p:] = np.add.reduceat(np.einsum("cik,ci->ik", jsd, rd), at, axis=0).ravel()
        for k in range(n):
            c = slice(p + k * NV, p + (k + 1) * NV)
            A[c, c] = Ass[k]
            A[:p, c] = Aps[k]
            A[c, :p] = Aps[k].T
        if r.shape[0] > nd:
            if v is None:
                raise ValueError("normal_equations: the tie residuals need the candidate v")
            T = self.tie_state_jacobian(v)
            A[p:, p:] += T.T @ T
            A[:p, p:] += Jx[nd:].T @ T
            A[p:, :p] = A[:p, p:].T
            g[p:] += T.T @ r[nd:]
        return A, g

    def full_state_jacobian(self, Js: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The compact state Jacobian ``Js[nd, NV]`` of candidate ``v`` spread to every
        segment's states ``[nd, n_seg*NV]``, the tie rows (if any) analytic."""
        nd = self.n_data
        owner = np.tile(self._gather()[0], len(self.base.channels))
        F = np.zeros((Js.shape[0], self.seg.n * NV))
        rows = np.arange(nd)
        for s in range(NV):
            F[rows, owner * NV + s] = Js[:nd, s]
        if Js.shape[0] > nd:
            F[nd:] = self.tie_state_jacobian(v)
        return F

    def groups(self) -> list[np.ndarray]:
        """Residual indices of each segment (its data samples of every channel, and the tie
        to the next segment): the clusters of the robust covariance."""
        b = self.base
        N, n_ch = b.log.n, len(b.channels)
        owner, _ = self._gather()
        tie = self.tie_data() is not None
        nd = n_ch * N
        return [np.concatenate([c * N + np.flatnonzero(owner == k) for c in range(n_ch)]
                               + ([np.array([nd + k])] if tie and k < self.seg.n - 1 else []))
                for k in range(self.seg.n)]


Z_SPEED = 0.01
"""The bristle state a segment starts with goes from -g/sigma0 to +g/sigma0 over motor speeds
of about this x vs (tanh) instead of jumping at 0 [-]: the LuGre steady state jumps with the
sign of the speed, and a jump in a segment's start makes its cost jump with the motor speed
state. A segment that starts at rest (the first one of a log) then stopped every joint
Levenberg-Marquardt step: a step moved its speed off 0 by a hair, its friction torque by the
whole Fc, and its cost rose by thousands (measured on a battery log: +8,690 for a step
predicted to lower it by 18)."""


def steady_z(prm: dict, w_m: np.ndarray) -> np.ndarray:
    """The LuGre bristle state a segment starting at motor speed ``w_m`` [rad/s] starts with
    -> z [rad] (0 without friction): the steady sliding state ``g(w)/sigma0``, g = Fc + (Fs -
    Fc)*exp(-|w/vs|^delta), signed by ``tanh(w/(Z_SPEED*vs))``, continuous through w = 0
    (:data:`Z_SPEED`)."""
    if prm["friction"] <= 0 or prm["sigma0"] <= 0:
        return np.zeros_like(w_m)
    g = prm["Fc"] + (prm["Fs"] - prm["Fc"]) * np.exp(-np.abs(w_m / prm["vs"]) ** prm["delta"])
    return np.tanh(w_m / (Z_SPEED * prm["vs"])) * g / prm["sigma0"]


def state_scales(problem: ClosedLoopProblem, guess: np.ndarray) -> np.ndarray:
    """Scale of each state [N_X] (SI): :data:`STATE_SCALE_FRACTION` of its RMS along the
    reconstructed trajectory ``guess[n, N_X]``, at least a tiny absolute floor."""
    rms = np.sqrt(np.mean(guess**2, axis=0))
    floor = np.array([1e-4, 1e-3, 1e-3, 1e-5, 1e-4, 1e-7, 1e-5])
    out = np.maximum(STATE_SCALE_FRACTION * rms, floor)
    out[0] = Q_SCALE
    return out

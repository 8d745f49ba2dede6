"""Output-error refinement of an inverse-model estimate in closed loop (DIDIM: Gautier, Janot and
Vandanjon, IEEE TCST 2013): the axis described by an actuator description, driven by the
record's reference through the described digital controller, simulated by the kernel; the
parameters moved until the simulated actuation force and position match the measured ones.

For a record with samples ``k = 0 .. n-1`` (period ``Ts``, the controller's) the residuals are::

    r_F[k] = (F_sim[k] - F[k]) / s_F        the actuation force [N] (EMPS: gtau*vir)
    r_q[k] = (q_sim[k] - q[k]) / s_q        the measured position [m]

over the samples the fit uses (a window, a time split). ``s_F`` and ``s_q`` are each channel's
own level, estimated from the data: the Gaussian maximum-likelihood estimate with an unknown
variance per channel weights each channel by the RMS of its residual at the current estimate
(:func:`channel_levels`; iterated), floored by the channel's noise floor (the encoder's
resolution over sqrt(12), the command's sample-to-sample noise): never a fraction of a range.
A model of a real machine does not reach the noise floor, and a weight at the floor would hand
the whole fit to one channel.

The kernel's parameters that each inverse-model term moves (:data:`TERM_PARAMS`): the mass, the
load-side friction (Coulomb levels with their static levels when the description's law has
static = Coulomb, viscous, per direction or both directions together) and the offset. Every
lane of one kernel call is a parameter set, so the base point and its ``p`` perturbations (the
forward-difference Jacobian) cost one call.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.errors import EmaError

FD_REL_STEP = 1e-3  # forward-difference step relative to the parameter's scale [-]
TERM_PARAMS: dict[str, tuple[str, ...]] = {
    "M": ("JL",),
    "Fv": ("Fv_L", "Fv_L_neg"),
    "Fc": ("Fc_L", "Fc_L_neg"),
    "OF": ("offset",),
    "Fv+": ("Fv_L",),
    "Fv-": ("Fv_L_neg",),
    "Fc+": ("Fc_L",),
    "Fc-": ("Fc_L_neg",),
}
"""Inverse-model term -> the kernel parameters set to its value (SI; the mass term sets the
load's mass, the motor's reflected inertia ``m^2 Jm`` added to it: :func:`mass_offset`)."""
STATIC_OF = {"Fc_L": "Fs_L", "Fc_L_neg": "Fs_L_neg"}
"""A Coulomb level -> its static level, moved with it when the description has static =
Coulomb (no stiction peak)."""


@dataclass
class ClosedLoopPlant:
    """What one closed-loop simulation of a record needs, resolved once.

    base        the description's parameters before derivation (``RunConfig.plant_overrides``)
    resolve     base dict -> complete SI parameter row (derivations applied)
    signal      the record's reference (and disturbance input) as the kernel's input
    dt, n_steps, dec   the kernel's step [s], steps, and steps per controller sample
    n           the record's samples compared (0 .. n-1, sample k at k*Ts)
    names       the free terms (inverse-model names), ``params_of`` the kernel parameters each sets
    static_follows     True: Fs follows Fc (static = Coulomb in the description)
    mass_extra  the motor's reflected inertia in load units [kg or kg*m^2] (rigid axis)
    """

    base: dict[str, Any]
    resolve: Any
    signal: Any
    dt: float
    n_steps: int
    dec: int
    n: int
    names: tuple[str, ...]
    static_follows: bool
    mass_extra: float = 0.0
    calls: int = 0
    kernel_s: float = 0.0
    load_s: float = 0.0
    lanes_run: int = 0
    cache: dict[bytes, tuple[np.ndarray, ...]] = field(default_factory=dict)

    def overrides(self, x: np.ndarray) -> dict[str, Any]:
        """The description's parameters with the free terms set to ``x`` (SI)."""
        out = dict(self.base)
        for name, v in zip(self.names, x, strict=True):
            if name not in TERM_PARAMS:  # a kernel parameter freed as itself
                out[name] = float(v)
                continue
            for p in TERM_PARAMS[name]:
                val = float(v) - self.mass_extra if name == "M" else float(v)
                out[p] = val
                if self.static_follows and p in STATIC_OF:
                    out[STATIC_OF[p]] = val
        return out

    def simulate(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every row of ``X[c, p]`` simulated -> (force [c, n] N, position [c, n] m) at the
        record's samples. Rows already run are taken from a cache."""
        from ema_cli.model.params import INDEX, to_row
        from ema_cli.sim.runner import simulate_batch

        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        todo = [i for i, x in enumerate(X) if x.tobytes() not in self.cache]
        if todo:
            P = np.array([to_row(self.resolve(self.overrides(X[i]))) for i in todo])
            res = simulate_batch(P, [self.signal], None, self.dt, self.n_steps, self.dec,
                                 parallel=True)
            self.calls += 1
            self.lanes_run += len(todo)
            self.kernel_s += res.kernel_s
            self.load_s += res.load_s
            if res.diverged.any():
                bad = X[todo[int(np.flatnonzero(res.diverged)[0])]]
                raise EmaError("the closed-loop simulation diverged at "
                               + ", ".join(f"{n}={v:.6g}" for n, v in zip(self.names, bad,
                                                                         strict=True))
                               + "; expected a stable loop (check the controller description)")
            if len(self.cache) > 64:
                self.cache.clear()
            for j, i in enumerate(todo):
                f = res.signal("drive_force", j)[:self.n].copy()
                q = res.signal("theta_load", j)[:self.n].copy()
                v = res.signal("omega_load", j)[:self.n].copy()
                net = f - res.signal("friction_load", j)[:self.n] \
                    + res.signal("torque_load", j)[:self.n]
                row = P[j]
                mass = row[INDEX["JL"]] + row[INDEX["m"]] ** 2 * row[INDEX["Jm"]]
                self.cache[X[i].tobytes()] = (f, q, v, net / mass)
        F = np.stack([self.cache[x.tobytes()][0] for x in X])
        Q = np.stack([self.cache[x.tobytes()][1] for x in X])
        return F, Q

    def motion(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The simulated force [N], position [m], velocity [m/s] and the model's acceleration
        (net force over the mass) [m/s^2] at the record's samples, for one parameter set."""
        x = np.asarray(x, dtype=np.float64)
        self.simulate(x[None])
        return self.cache[x.tobytes()]  # type: ignore[return-value]


@dataclass(frozen=True)
class Channels:
    """The measured channels compared: force ``F`` [N], position ``q`` [m] at the record's
    samples; ``use`` the samples in the cost (bool [n]); ``floor_F``, ``floor_q`` the noise
    floors [N], [m]."""

    F: np.ndarray
    q: np.ndarray
    use: np.ndarray
    floor_F: float
    floor_q: float


def encoder_floor(q: np.ndarray) -> float:
    """The position's resolution over sqrt(12) [m]: the smallest spacing between the distinct
    values it takes (the median of the sorted distinct values' differences within 1.5x the
    smallest one above rounding), the standard deviation of a uniform quantiser of that step.
    A signal that is not quantised gives its finest spacing."""
    u = np.unique(np.asarray(q, dtype=np.float64))
    d = np.diff(u)
    d = d[d > 1e-12 * max(float(np.max(np.abs(u))), 1e-300)]
    if d.size == 0:
        return 0.0
    return float(np.median(d[d < 1.5 * d.min()])) / np.sqrt(12.0)


def command_floor(F: np.ndarray) -> float:
    """The actuation's sample-to-sample noise [N]: the median absolute third difference scaled
    to a standard deviation (white noise e: var(Δ^3 e) = 20 var(e); MAD -> sigma 1.4826), robust
    to the motion's own (smooth) part and its jumps."""
    d3 = np.diff(F, 3)
    return float(1.4826 * np.median(np.abs(d3 - np.median(d3))) / np.sqrt(20.0))


def channel_levels(plant: ClosedLoopPlant, ch: Channels, x: np.ndarray) -> tuple[float, float]:
    """Each channel's residual RMS at ``x`` over the used samples, floored by its noise floor
    -> (s_F [N], s_q [m]): the maximum-likelihood weights of a Gaussian with one unknown
    variance per channel."""
    F, Q = plant.simulate(x[None])
    rF = F[0][ch.use] - ch.F[ch.use]
    rq = Q[0][ch.use] - ch.q[ch.use]
    sF = max(float(np.sqrt(np.mean(rF**2))), ch.floor_F, 1e-12)
    sq = max(float(np.sqrt(np.mean(rq**2))), ch.floor_q, 1e-15)
    return sF, sq


def residuals(plant: ClosedLoopPlant, ch: Channels, X: np.ndarray, s: tuple[float, float]
              ) -> np.ndarray:
    """Weighted residuals ``[r_F, r_q]`` of every row of ``X`` -> [c, 2 m] (m used samples)."""
    F, Q = plant.simulate(X)
    rF = (F[:, ch.use] - ch.F[ch.use]) / s[0]
    rq = (Q[:, ch.use] - ch.q[ch.use]) / s[1]
    return np.concatenate([rF, rq], axis=1)


def fd_jacobian(plant: ClosedLoopPlant, ch: Channels, x: np.ndarray, scale: np.ndarray,
                s: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Forward-difference Jacobian of the weighted residuals at ``x`` -> (r, J[N, p]); the base
    point and the p perturbed sets in one kernel call (steps ``FD_REL_STEP * scale``)."""
    p = x.shape[0]
    h = FD_REL_STEP * scale
    X = np.repeat(x[None], p + 1, axis=0)
    for j in range(p):
        X[1 + j, j] += h[j]
    R = residuals(plant, ch, X, s)
    return R[0], (R[1:] - R[0]).T / h[None, :]


@dataclass
class OutputErrorFit:
    """The result of :func:`fit`: ``x`` the estimate (SI, order of ``names``), ``r`` the weighted
    residuals and ``J`` their Jacobian there, ``levels`` (s_F, s_q), ``cost_history`` the cost
    0.5 r.r after each Gauss-Newton step, ``iterations``, ``converged`` (the last step moved
    every parameter by less than ``tol`` of its scale), ``status`` a sentence."""

    names: tuple[str, ...]
    x: np.ndarray
    r: np.ndarray
    J: np.ndarray
    levels: tuple[float, float]
    cost_history: list[float]
    iterations: int
    converged: bool
    status: str


def fit(plant: ClosedLoopPlant, ch: Channels, x0: np.ndarray, scale: np.ndarray,
        lower: np.ndarray, upper: np.ndarray, max_iter: int = 20, tol: float = 1e-4,
        progress: Any = None) -> OutputErrorFit:
    """Levenberg-Marquardt on the weighted residuals from ``x0`` (the IDIM-LS estimate), the
    channel levels re-estimated after each accepted step (iteratively reweighted maximum
    likelihood); ``scale`` the parameters' scales (their IDIM standard errors times 10, or
    values), bounds ``lower``/``upper``. Stops when a step moves every parameter by less than
    ``tol`` of its scale and the levels are settled."""
    x = np.clip(np.asarray(x0, dtype=np.float64), lower, upper)
    s = channel_levels(plant, ch, x)
    lam = 1e-3
    hist: list[float] = []
    r, J = fd_jacobian(plant, ch, x, scale, s)
    converged = False
    status = f"stopped after {max_iter} iterations without settling"
    it = 0
    for it in range(1, max_iter + 1):
        cost = 0.5 * float(r @ r)
        hist.append(cost)
        Js = J * scale[None, :]
        A = Js.T @ Js
        g = Js.T @ r
        accepted = False
        for _ in range(8):
            D = np.diag(np.diag(A)) * lam + np.eye(len(x)) * 1e-12 * np.trace(A)
            step = -np.linalg.solve(A + D, g) * scale
            x_new = np.clip(x + step, lower, upper)
            r_new = residuals(plant, ch, x_new[None], s)[0]
            if 0.5 * float(r_new @ r_new) < cost:
                accepted = True
                break
            lam *= 10.0
        if progress is not None:
            progress(it, max_iter, cost)
        if not accepted:
            converged = True
            status = "no step lowers the cost: at a minimum"
            break
        moved = np.abs(x_new - x) / scale
        x = x_new
        lam = max(lam / 10.0, 1e-7)
        s_new = channel_levels(plant, ch, x)
        settled = max(abs(s_new[0] / s[0] - 1.0), abs(s_new[1] / s[1] - 1.0)) < 1e-3
        s = s_new
        r, J = fd_jacobian(plant, ch, x, scale, s)
        if np.all(moved < tol) and settled:
            converged = True
            status = f"converged: the last step moved every parameter by < {tol:g} of its scale"
            break
    hist.append(0.5 * float(r @ r))
    return OutputErrorFit(plant.names, x, r, J, s, hist, it, converged, status)


MIN_CLUSTERS = 20  # independent residual blocks a verdict needs [-]
BLOCK_CORR = 20.0  # residual blocks of at least this many correlation times [-]
BLOCK_MIN_S = 0.25  # ... and at least this long [s]


def block_length(corr_time_s: float, n: int, h_s: float) -> float:
    """The length [s] of the residual blocks of a cluster-robust covariance over ``n``
    samples every ``h_s``: :data:`BLOCK_CORR` correlation times and at least
    :data:`BLOCK_MIN_S`, shortened to leave :data:`MIN_CLUSTERS` blocks when the record allows."""
    block = max(BLOCK_CORR * corr_time_s, BLOCK_MIN_S)
    return min(block, max(n * h_s / MIN_CLUSTERS, h_s))


def time_blocks(n: int, h_s: float, block_s: float) -> list[np.ndarray]:
    """Contiguous blocks of ``block_s`` seconds of ``n`` samples every ``h_s`` (index arrays;
    a short tail joins the previous block)."""
    per = max(int(round(block_s / h_s)), 1)
    out: list[np.ndarray] = []
    for a in range(0, n, per):
        b = min(a + per, n)
        if b - a < per // 2 and out:
            out[-1] = np.concatenate([out[-1], np.arange(a, b)])
        else:
            out.append(np.arange(a, b))
    return out


def time_clusters(use: np.ndarray, h_s: float, block_s: float) -> list[np.ndarray]:
    """Clusters of the weighted residual vector ``[r_F, r_q]`` (both channels over the used
    samples): the :func:`time_blocks` of ``block_s`` seconds, each holding both channels'
    residuals of its samples."""
    m = int(np.count_nonzero(use))
    return [np.concatenate([c, m + c]) for c in time_blocks(m, h_s, block_s)]


def correlation_time(r: np.ndarray, h_s: float, max_lag: int | None = None) -> float:
    """The residual's correlation time [s]: the first lag where its autocorrelation drops
    below 1/e (at least one sample)."""
    x = r - r.mean()
    n = x.size
    if n < 4 or not np.any(x):
        return h_s
    spec = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(spec * np.conj(spec))[:n]
    ac /= ac[0]
    max_lag = n // 2 if max_lag is None else max_lag
    below = np.flatnonzero(ac[:max_lag] < np.exp(-1.0))
    return float((below[0] if below.size else max_lag) * h_s)


def law_terms(law: str | Sequence[str]) -> tuple[str, ...]:
    """A law's inverse-model terms: ``symmetric`` (M, Fv, Fc, OF), ``per-direction`` (M, Fv+,
    Fc+, Fv-, Fc-: the offset is the Coulomb levels' difference when the axis never rests) or
    a list of :data:`TERM_PARAMS` names."""
    if isinstance(law, str):
        if law == "symmetric":
            return ("M", "Fv", "Fc", "OF")
        if law == "per-direction":
            return ("M", "Fv+", "Fc+", "Fv-", "Fc-")
        raise EmaError(f"law '{law}'; expected symmetric, per-direction or a list of terms "
                       f"({', '.join(TERM_PARAMS)})")
    bad = [t for t in law if t not in TERM_PARAMS]
    if bad:
        raise EmaError(f"unknown term(s) {', '.join(bad)}; expected {', '.join(TERM_PARAMS)}")
    return tuple(law)


def params_of(x: Mapping[str, float]) -> dict[str, float]:
    """An estimate by term name -> the kernel parameters it sets (for a description's
    overrides or a report)."""
    out: dict[str, float] = {}
    for name, v in x.items():
        for p in TERM_PARAMS[name]:
            out[p] = float(v)
    return out

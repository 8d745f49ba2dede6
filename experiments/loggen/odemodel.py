"""The closed-loop EMA of docs/model.md §1-§2 as an ODE ``dx/dt = f(t, x, params, command)``,
integrated by scipy ``solve_ivp`` (Radau) with events at every contact entry and exit and at
the current limit. Written apart from ema's kernel: nothing from ``ema_cli`` is imported.

States (SI): ``x = [theta_m, w_m, i, theta_L, w_L, z, xI]`` (rad, rad/s, A, rad, rad/s, rad,
rad), all 0 at t = 0 (at rest).

Continuous controller (load-angle feedback, no quantisers)::

    e_th = theta_ref - DZ(theta_L, d4)        w*_m = m*SAT(Kpp*e_th, sat1)
    e_w  = w*_m - DZ(w_m, d3)                 u_unsat = Kps*e_w + Kis*xI
    u_dem = SAT(u_unsat, sat2)                dxI/dt = 0 if |u_unsat| > sat2 and e_w*u_unsat > 0
                                                       else e_w   (clamping anti-windup)
    L*di/dt = DZ(u_dem, d1) - R*i - Ke*w_m    (current limit: see below)

Motor, LuGre friction (z an ODE state: stiff, rate sigma0*|w_m|/g up to ~1e5 1/s), load::

    g = Fc + (Fs - Fc)*exp(-|w_m/vs|^delta)   dz/dt = w_m - sigma0*|w_m|/g*z
    Tf = sigma0*z + sigma1*dz/dt + sigma2*w_m
    Jm*dw_m/dt = Kt*i - bm*w_m - T/m - Tf     JL*dw_L/dt = T - bL*w_L

Transmission, ``dth = theta_m/m - theta_L``, ``dw = w_m/m - w_L`` (load side), contact laws
with backlash ``alpha > 0`` (``alpha = 0``: a linear shaft ``T = kL*dth + c*dw`` for every
law). In contact on the + side (``pen = dth - alpha > 0``; the - side mirrors it)::

    jump:          T = max(kL*pen + c*dw, 0)                      (ema's contact_tau = 0)
    ramp:          T = max(kL*pen + c*clip(dw, -pen/tau, pen/tau), 0)  (ema's default, tau)
    hunt_crossley: T = max(kL*pen*(1 + lam*dw), 0)                (foreign to ema)

and T = 0 in the gap. Hunt-Crossley's damping ``kL*lam*pen`` grows with the penetration; lam
is set per truth so that it equals the viscous ``c`` at the penetration :data:`HC_PEN_REF`
(see :func:`hc_lambda`).

Hybrid integration. The contact side (-1, 0, +1) and the current-limit state (-1, 0, +1) are
discrete modes held constant over each ``solve_ivp`` call; terminal events at
``dth = +-alpha`` and ``i = +-sat3`` (and, inside the limit, at the sign change of the
unlimited di/dt) end the call, switch the mode and restart the integrator. So every
discontinuity of the right-hand side of the contact laws and of the current limit falls on a
step boundary. The current limit as documented: while the limit holds (entered when |i|
reaches sat3 with di/dt pushing outward, i then set to exactly +-sat3) ``di/dt =
s*min(s*f_i, 0)``: i is held until the unlimited ``f_i`` turns inward, which is the event
that leaves the limit (f_i = 0 there: di/dt is continuous at the exit). The remaining
non-smooth points (SAT1, SAT2, the anti-windup switch, ``|w_m|`` in LuGre) are left to the
step-size control (the anti-windup switch is a jump of dxI/dt, the others kinks).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

STATES = ("theta_m", "w_m", "i", "theta_L", "w_L", "z", "xI")
STATE_SCALE = np.array([2.0, 200.0, 30.0, 0.1, 10.0, 2.0e-3, 2.0])
"""Typical magnitude of each state in the battery's logs [SI]: atol = rtol*scale."""
LAWS = ("jump", "ramp", "hunt_crossley")
METHOD = "Radau"  # implicit, L-stable, order 5: the bristle state is stiff
RTOL = 1.0e-9  # relative tolerance of the logs [-]
MAX_STEP = 2.0e-4  # largest step [s]: 1/50 of the shortest contact half-period (~10 ms)
HC_PEN_REF = 1.0e-3  # Hunt-Crossley: penetration at which its damping equals c [rad]
ZERO_PROGRESS_LIMIT = 200  # consecutive events without time progress before giving up [-]


def hc_lambda(p: Mapping[str, float]) -> float:
    """Hunt-Crossley coefficient lam [s/rad]: ``kL*lam*HC_PEN_REF = c``, i.e. the
    penetration-proportional damping equals the viscous laws' c at HC_PEN_REF."""
    return p["c"] / (p["kL"] * HC_PEN_REF)


@dataclass
class Stats:
    """What one integration did: segments, events per kind, evaluations, time."""

    segments: int = 0
    contact_events: int = 0
    ilim_entries: int = 0
    time_in_ilim_s: float = 0.0
    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    wall_s: float = 0.0
    max_zero_progress: int = 0

    def to_json(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Plant:
    """Parameters (SI, resolved), contact law and command of one closed-loop run."""

    p: Mapping[str, float]
    law: str
    command: Callable[[float], float]
    lam: float = field(init=False)

    def __post_init__(self) -> None:
        if self.law not in LAWS:
            raise ValueError(f"unknown contact law '{self.law}'; expected one of {LAWS}")
        self.lam = hc_lambda(self.p)
        q = self.p
        self._c = (q["R"], q["L"], q["Kt"], q["Ke"], q["Jm"], q["bm"], q["m"], q["JL"],
                   q["bL"], q["kL"], q["c"], q["alpha"], q["contact_tau"], q["Kpp"], q["Kps"],
                   q["Kis"], q["sat1"], q["sat2"], q["d1"], q["d3"], q["d4"], q["Fc"], q["Fs"],
                   q["vs"], q["delta"], q["sigma0"], q["sigma1"], q["sigma2"])
        self._law = LAWS.index(self.law)

    # -- controller ---------------------------------------------------------------------------
    def control(self, t: float, x) -> tuple[float, float, float, float]:
        """-> (e_w [rad/s], u_unsat [V], u_dem [V], f_i [A/s] the unlimited di/dt)."""
        (R, L, _, Ke, _, _, m, _, _, _, _, _, _, Kpp, Kps, Kis, sat1, sat2, d1, d3, d4,
         *_) = self._c
        th_L = x[3]
        w_m = x[1]
        th_meas = th_L - min(max(th_L, -d4), d4)
        w_meas = w_m - min(max(w_m, -d3), d3)
        wls = min(max(Kpp * (self.command(t) - th_meas), -sat1), sat1)
        e_w = m * wls - w_meas
        u_unsat = Kps * e_w + Kis * x[6]
        u_dem = min(max(u_unsat, -sat2), sat2)
        u_amp = u_dem - min(max(u_dem, -d1), d1)
        return e_w, u_unsat, u_dem, (u_amp - R * x[2] - Ke * w_m) / L

    # -- transmission -------------------------------------------------------------------------
    def torque(self, dth: float, dw: float, contact: int) -> float:
        """Shaft torque T [N*m] for deflection dth [rad], rate dw [rad/s], contact side."""
        kL, c, alpha, tau = self._c[9], self._c[10], self._c[11], self._c[12]
        if alpha == 0.0:
            return kL * dth + c * dw
        if contact == 0:
            return 0.0
        s = float(contact)
        pen = s * dth - alpha  # penetration, > 0 in contact (tiny either side at an event)
        vpen = s * dw  # penetration rate
        if self._law == 0:  # jump
            tc = kL * pen + c * vpen
        elif self._law == 1:  # ramp
            lim = max(pen, 0.0) / tau if tau > 0 else math.inf
            tc = kL * pen + c * min(max(vpen, -lim), lim)
        else:  # hunt_crossley
            tc = kL * pen * (1.0 + self.lam * vpen)
        return s * max(tc, 0.0)

    # -- right-hand side ----------------------------------------------------------------------
    def rhs(self, t: float, x, contact: int, ilim: int) -> list[float]:
        """dx/dt [SI] in the mode (contact side, current-limit side)."""
        (_, _, Kt, _, Jm, bm, m, JL, bL, _, _, _, _, _, _, _, _, sat2, *_,
         Fc, Fs, vs, delta, sigma0, sigma1, sigma2) = self._c
        w_m, z = x[1], x[5]
        e_w, u_unsat, _, f_i = self.control(t, x)
        dxI = 0.0 if (abs(u_unsat) > sat2 and e_w * u_unsat > 0.0) else e_w
        di = f_i if ilim == 0 else ilim * min(ilim * f_i, 0.0)
        T = self.torque(x[0] / m - x[3], w_m / m - x[4], contact)
        aw = abs(w_m)
        g = Fc + (Fs - Fc) * math.exp(-((aw / vs) ** delta))
        dz = w_m - sigma0 * aw / g * z
        Tf = sigma0 * z + sigma1 * dz + sigma2 * w_m
        dw_m = (Kt * x[2] - bm * w_m - T / m - Tf) / Jm
        dw_L = (T - bL * x[4]) / JL
        return [w_m, dw_m, di, x[4], dw_L, dz, dxI]

    def events(self, contact: int, ilim: int, sat3: float) -> list[tuple[Callable, str]]:
        """Terminal events leaving the mode -> [(event function, what it switches)]."""
        m, alpha = self._c[6], self._c[11]
        out: list[tuple[Callable, str]] = []

        def ev(fun: Callable, direction: float, what: str) -> None:
            fun.terminal = True  # type: ignore[attr-defined]
            fun.direction = direction  # type: ignore[attr-defined]
            out.append((fun, what))

        if alpha > 0.0:
            if contact == 0:
                ev(lambda t, x, *a: x[0] / m - x[3] - alpha, 1.0, "contact+")
                ev(lambda t, x, *a: x[0] / m - x[3] + alpha, -1.0, "contact-")
            elif contact == 1:
                ev(lambda t, x, *a: x[0] / m - x[3] - alpha, -1.0, "gap")
            else:
                ev(lambda t, x, *a: x[0] / m - x[3] + alpha, 1.0, "gap")
        if math.isfinite(sat3):
            if ilim == 0:
                ev(lambda t, x, *a: x[2] - sat3, 1.0, "ilim+")
                ev(lambda t, x, *a: x[2] + sat3, -1.0, "ilim-")
            else:
                ev(lambda t, x, *a: ilim * self.control(t, x)[3], -1.0, "free")
        return out


@dataclass
class Trajectory:
    """States at the sample times and the voltage demand there, with the run's statistics."""

    t: np.ndarray  # [s], shape (n,)
    x: np.ndarray  # [SI], shape (n, 7), columns STATES
    u_dem: np.ndarray  # voltage demand after SAT2 [V], shape (n,)
    theta_ref: np.ndarray  # the command at the samples [rad]
    stats: Stats
    sat2_reached: bool
    sat1_reached: bool

    def state(self, name: str) -> np.ndarray:
        return self.x[:, STATES.index(name)]


def simulate(p: Mapping[str, float], law: str, command: Callable[[float], float],
             t_samples: np.ndarray, *, rtol: float = RTOL, max_step: float = MAX_STEP,
             method: str = METHOD) -> Trajectory:
    """Integrate the closed loop from rest over [0, t_samples[-1]] with the analytic command
    ``command(t)`` [rad] and return the states at ``t_samples`` [s] (increasing, from 0).
    ``atol = rtol*STATE_SCALE``. Raises RuntimeError when an integration step fails."""
    ts = np.asarray(t_samples, dtype=float)
    if ts.ndim != 1 or ts[0] < 0 or np.any(np.diff(ts) <= 0):
        raise ValueError("t_samples must be increasing from t >= 0")
    plant = Plant(p, law, command)
    sat3 = p["sat3"]
    atol = rtol * STATE_SCALE
    st = Stats()
    wall0 = time.perf_counter()
    t0, x0 = 0.0, np.zeros(len(STATES))
    contact, ilim = 0, 0
    rec_t: list[np.ndarray] = []
    rec_x: list[np.ndarray] = []
    k = 0  # next sample to record
    zero_run = 0
    t_end = float(ts[-1])
    while t0 < t_end:
        evs = plant.events(contact, ilim, sat3)
        sol = solve_ivp(plant.rhs, (t0, t_end), x0, method=method, t_eval=ts[k:],
                        events=[e for e, _ in evs] or None, args=(contact, ilim), rtol=rtol,
                        atol=atol, max_step=max_step)
        st.segments += 1
        st.nfev += sol.nfev
        st.njev += sol.njev
        st.nlu += sol.nlu
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp failed after t = {t0:.6g} s ({law}): {sol.message}")
        seg_t = np.asarray(sol.t, dtype=float)  # solve_ivp gives [] when no sample fell in
        if seg_t.size:
            rec_t.append(seg_t)
            rec_x.append(np.asarray(sol.y, dtype=float).T)
            k += seg_t.size
        if sol.status == 0:
            if ilim:
                st.time_in_ilim_s += t_end - t0
            break
        # a terminal event: the earliest one (solve_ivp stops at the first)
        hits = [(float(te[0]), j) for j, te in enumerate(sol.t_events) if te.size]
        te, j = min(hits)
        xe = np.array(sol.y_events[j][0], dtype=float)
        what = evs[j][1]
        if ilim:
            st.time_in_ilim_s += te - t0
        if what in ("contact+", "contact-"):
            contact = 1 if what == "contact+" else -1
            st.contact_events += 1
        elif what == "gap":
            contact = 0
            st.contact_events += 1
        elif what in ("ilim+", "ilim-"):
            s = 1 if what == "ilim+" else -1
            if s * plant.control(te, xe)[3] > 0.0:  # pushing outward: the limit holds
                ilim = s
                xe[2] = s * sat3
                st.ilim_entries += 1
        else:  # "free": the unlimited di/dt turned inward
            ilim = 0
        zero_run = zero_run + 1 if te - t0 <= 1e-13 * max(1.0, te) else 0
        st.max_zero_progress = max(st.max_zero_progress, zero_run)
        if zero_run > ZERO_PROGRESS_LIMIT:
            raise RuntimeError(f"{ZERO_PROGRESS_LIMIT} events without progress at t = {te:.9g} s "
                               f"({law}, last event {what}): chattering between modes")
        t0, x0 = te, xe
    st.wall_s = time.perf_counter() - wall0
    t = np.concatenate(rec_t)
    x = np.concatenate(rec_x)
    if t.size != ts.size or not np.array_equal(t, ts):
        raise RuntimeError(f"recorded {t.size} of {ts.size} samples")
    ctl = np.array([plant.control(float(tt), xx) for tt, xx in zip(t, x, strict=True)])
    theta_ref = np.array([command(float(tt)) for tt in t])
    sat1_hit = bool(np.any(np.abs(p["Kpp"] * (theta_ref - x[:, 3])) >= p["sat1"]))
    return Trajectory(t, x, ctl[:, 2], theta_ref, st, bool(np.any(np.abs(ctl[:, 1]) > p["sat2"])),
                      sat1_hit)

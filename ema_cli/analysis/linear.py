"""The model's linear limit as a state-space system, its frequency responses and loop margins.

Linear limit (docs/model.md §2 with every nonlinearity removed): saturations SAT1-3 open, no
dead zones, no backlash (``alpha`` ignored: permanent contact), no quantisers, a continuous
controller, and LuGre friction linearised to its viscous part (``sigma2*w_m`` when friction is
on). The constant load torque only moves the operating point and drops out; the hinge-moment
gradient ``k_h`` stays. Of the compensators, the viscous friction feed-forward and the notch are
linear and stay; the dead-zone inverse goes with the dead zone it inverts, and the Coulomb part
of the feed-forward with the friction it cancels.

States ``x = [theta_m, w_m, i, theta_L, w_L, xI]`` (+ ``xn1, xn2`` with a notch) (SI), inputs
``u = [theta_ref, T_d]`` (a torque disturbance on the load, + along +theta_L), outputs
``y = [theta_L, w_L, theta_m, w_m, i, u_dem]``:

    dtheta_m = w_m
    Jm dw_m  = Kt i - (bm + f) w_m - T/m             f = sigma2 if friction on, else 0
    L di     = u_dem - R i - Ke w_m
    dtheta_L = w_L
    JL dw_L  = T - bL w_L - k_h theta_L + T_d
    dxI      = e_w
    T        = kL (theta_m/m - theta_L) + c (w_m/m - w_L)
    u_dem    = Kps e_w + Kis xI + k_ff w_m (+ notch),   e_w = w*_m - w_m,
    w*_m     = m Kpp (theta_ref - theta_fb),   k_ff = R/Kt * ff_sigma2 (viscous compensation)
    theta_fb = (1 - b) theta_L + b theta_m / m     (b = fb_motor: 0 load sensor, 1 motor)

Loops are broken at their feedback (the measured position theta_fb for the position loop, the
measured motor speed at the speed PI for the speed loop) with the other loop closed; the
viscous friction compensation keeps reading the motor speed (it belongs to the compensated
motor, around which the speed loop is closed). The loop transfer is
``L(s) = -(return at the break)/(injection)``, so the closed loop is stable when the Nyquist
curve of ``L`` obeys the usual criterion and ``1 + L`` is the return difference.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from ema_cli.errors import EmaError

STATE_NAMES = ("theta_m", "w_m", "i", "theta_L", "w_L", "xI")
INPUT_NAMES = ("theta_ref", "torque_disturbance")
OUTPUT_NAMES = ("theta_L", "w_L", "theta_m", "w_m", "i", "u_dem")
LOOPS = ("position", "speed")
LINEAR_PARAMS = ("m", "kL", "c", "Jm", "JL", "bm", "sigma2", "friction", "bL", "Kt", "Ke", "R",
                 "L", "k_h", "Kpp", "Kps", "Kis", "fb_motor", "ff_sigma2", "notch_hz",
                 "notch_depth", "notch_zeta")
"""The parameters the linear model reads (two parameter sets equal on these have one model)."""
MODAL_COND_MAX = 1.0e8  # frequency responses in modal form below this condition number of the
# eigenvector matrix (relative error ~ cond * 1e-16), by a direct solve above it


@dataclass(frozen=True)
class StateSpace:
    """``dx/dt = A x + B u``, ``y = C x + D u`` (SI), with names for states, inputs, outputs."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    def response(self, f_hz: np.ndarray, inp: str = "theta_ref",
                 out: str = "theta_L") -> np.ndarray:
        """The complex frequency response ``Y(j w)/U(j w)`` at ``f_hz`` [Hz]."""
        return self.evaluator(inp, out)(f_hz)

    def evaluator(self, inp: str = "theta_ref",
                  out: str = "theta_L") -> Callable[[np.ndarray], np.ndarray]:
        """A function ``f_hz -> Y(j w)/U(j w)`` (the decomposition done once, for repeated
        evaluation): the modal form ``sum_k (C V)_k (V^-1 B)_k / (s - lambda_k) + D`` when the
        eigenvectors are well conditioned, else a direct solve per frequency."""
        j = self.inputs.index(inp)
        k = self.outputs.index(out)
        n = self.A.shape[0]
        b = self.B[:, j].astype(complex)
        c = self.C[k]
        d = self.D[k, j]
        lam, V = np.linalg.eig(self.A)
        if np.linalg.cond(V) < MODAL_COND_MAX:
            res = (c @ V) * np.linalg.solve(V, b)

            def modal(f_hz: np.ndarray) -> np.ndarray:
                s = 2j * math.pi * np.atleast_1d(np.asarray(f_hz, dtype=np.float64))
                return (res[None, :] / (s[:, None] - lam[None, :])).sum(axis=1) + d
            return modal
        A = self.A

        def direct(f_hz: np.ndarray) -> np.ndarray:
            s = 2j * math.pi * np.atleast_1d(np.asarray(f_hz, dtype=np.float64))
            M = s[:, None, None] * np.eye(n)[None] - A[None]
            x = np.linalg.solve(M, np.broadcast_to(b, (s.shape[0], n))[..., None])[..., 0]
            return x @ c + d
        return direct


def _coefficients(p: Mapping[str, float]) -> dict[str, float]:
    m = p["m"]
    return {"m": m, "kL": p["kL"], "c": p["c"], "Jm": p["Jm"], "JL": p["JL"],
            "bm": p["bm"] + (p["sigma2"] if p["friction"] else 0.0), "bL": p["bL"],
            "Kt": p["Kt"], "Ke": p["Ke"], "R": p["R"], "L": p["L"], "kh": p["k_h"],
            "Kpp": p["Kpp"], "Kps": p["Kps"], "Kis": p["Kis"]}


def _plant_rows(q: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The open-loop plant: A_p (6x6, controller states included but unconnected), the column
    of u_dem and of the disturbance torque."""
    m, kL, c = q["m"], q["kL"], q["c"]
    A = np.zeros((6, 6))
    A[0, 1] = 1.0
    # Jm dw_m = Kt i - bm w_m - T/m, T = kL(th_m/m - th_L) + c(w_m/m - w_L)
    A[1, 0] = -kL / m**2 / q["Jm"]
    A[1, 1] = (-q["bm"] - c / m**2) / q["Jm"]
    A[1, 2] = q["Kt"] / q["Jm"]
    A[1, 3] = kL / m / q["Jm"]
    A[1, 4] = c / m / q["Jm"]
    # L di = u - R i - Ke w_m
    A[2, 1] = -q["Ke"] / q["L"]
    A[2, 2] = -q["R"] / q["L"]
    A[3, 4] = 1.0
    # JL dw_L = T - bL w_L - kh th_L + Td
    A[4, 0] = kL / m / q["JL"]
    A[4, 1] = c / m / q["JL"]
    A[4, 3] = (-kL - q["kh"]) / q["JL"]
    A[4, 4] = (-c - q["bL"]) / q["JL"]
    b_u = np.zeros(6)
    b_u[2] = 1.0 / q["L"]
    b_d = np.zeros(6)
    b_d[4] = 1.0 / q["JL"]
    return A, b_u, b_d


def linear_model(params: Mapping[str, float], broken: str | None = None) -> StateSpace:
    """The closed-loop linear limit of the EMA for the SI parameters ``params``.

    ``broken`` None: both loops closed, inputs ``theta_ref`` and ``torque_disturbance``.
    ``broken`` ``"position"`` or ``"speed"``: that loop's measurement is replaced by an
    injected signal ``v`` (the only input) and the output ``return`` is what the loop would
    have measured (theta_L, or w_m); the other loop stays closed. ``L(s) = -return/v``.
    """
    if broken not in (None, *LOOPS):
        raise EmaError(f"loop must be one of {', '.join(LOOPS)}, got {broken!r}")
    q = _coefficients(params)
    for name in ("m", "kL", "Jm", "JL", "L", "R"):
        if not (math.isfinite(q[name]) and q[name] > 0):
            raise EmaError(f"the linear model needs a finite {name} > 0, got {q[name]}")
    A6, b_u6, b_d6 = _plant_rows(q)
    m, Kpp, Kps, Kis = q["m"], q["Kpp"], q["Kps"], q["Kis"]
    f_n = float(params.get("notch_hz", 0.0))
    n = 8 if f_n > 0 else 6  # the notch adds its two states
    names = STATE_NAMES + (("xn1", "xn2") if n == 8 else ())
    A = np.zeros((n, n))
    A[:6, :6] = A6
    b_u = np.zeros(n)
    b_u[:6] = b_u6
    b_d = np.zeros(n)
    b_d[:6] = b_d6
    # rows over [x, theta_ref, v]: e_w = ew_x @ x + ew_r * theta_ref + ew_v * v, with
    # e_w = m Kpp (theta_ref - th_meas) - w_meas; ws: the measured motor speed w_meas
    ew_x = np.zeros(n)
    ew_v = 0.0
    ew_r = m * Kpp
    ws_x = np.zeros(n)
    ws_v = 0.0
    b = float(params.get("fb_motor", 0.0))  # position fed back: (1-b)*theta_L + b*theta_m/m
    if broken == "position":
        ew_v = -m * Kpp
    else:
        ew_x[3] = -m * Kpp * (1.0 - b)
        ew_x[0] = -Kpp * b
    # the friction compensator's measured speed stays closed when the speed loop is broken: the
    # speed loop is the PI's feedback, around the compensated motor
    ws_x[1] = 1.0
    if broken == "speed":
        ew_v -= 1.0  # the PI's measured motor speed is the injection
    else:
        ew_x[1] = -1.0
    # u_pre = Kps e_w + Kis xI + k_ff w_meas (the viscous friction compensation, R/Kt*ff_sigma2,
    # on the measured motor speed);
    # u = u_pre + c_n xn2 (the notch; xn1' = xn2, xn2' = -w^2 xn1 - 2 zeta w xn2 + u_pre)
    k_ff = q["R"] / q["Kt"] * float(params.get("ff_sigma2", 0.0))
    pre_x = Kps * ew_x + k_ff * ws_x
    pre_x[5] += Kis
    pre_r = Kps * ew_r
    pre_v = Kps * ew_v + k_ff * ws_v
    u_x = pre_x.copy()
    if n == 8:
        w_n = 2 * math.pi * f_n
        zeta = float(params.get("notch_zeta", 0.5))
        u_x[7] += 2.0 * (float(params.get("notch_depth", 0.1)) - 1.0) * zeta * w_n
    Acl = A + np.outer(b_u, u_x)
    Acl[5, :] += ew_x
    col_r = b_u * pre_r
    col_r[5] += ew_r
    col_v = b_u * pre_v
    col_v[5] += ew_v
    if n == 8:
        Acl[6, 7] += 1.0
        Acl[7, 6] -= w_n**2
        Acl[7, 7] -= 2.0 * zeta * w_n
        Acl[7, :] += pre_x
        col_r[7] += pre_r
        col_v[7] += pre_v
    C = np.zeros((6, n))
    for k, name in enumerate(("theta_L", "w_L", "theta_m", "w_m", "i")):
        C[k, names.index(name)] = 1.0
    C[5] = u_x
    if broken is None:
        B = np.column_stack([col_r, b_d])
        D = np.zeros((6, 2))
        D[5, 0] = pre_r
        return StateSpace(Acl, B, C, D, names, INPUT_NAMES, OUTPUT_NAMES)
    Cr = np.zeros((1, n))
    if broken == "position":
        Cr[0, names.index("theta_L")] = 1.0 - b
        Cr[0, names.index("theta_m")] = b / m
    else:
        Cr[0, names.index("w_m")] = 1.0
    return StateSpace(Acl, col_v[:, None], Cr, np.zeros((1, 1)), names, ("v",), ("return",))


def closed_loop_stable(params: Mapping[str, float]) -> bool:
    """Whether the closed linear loop (both loops closed) is asymptotically stable: every
    eigenvalue in the open left half-plane."""
    return bool(np.max(np.linalg.eigvals(linear_model(params).A).real) < 0.0)


def slowest_time_constant(params: Mapping[str, float]) -> float | None:
    """The slowest time constant of the closed linear loop (both loops closed) [s]:
    ``1/min |Re(lambda)|`` over the eigenvalues of :func:`linear_model`'s A, i.e. the time the
    slowest mode of a response needs to decay by e. None when the linear loop is not
    asymptotically stable (no decay to speak of)."""
    re = np.linalg.eigvals(linear_model(params).A).real
    if not np.all(re < 0.0):
        return None
    return float(1.0 / np.min(-re))


@dataclass(frozen=True)
class Margins:
    """Stability margins of one loop: gain margin [dB] at the phase crossover [Hz], phase
    margin [deg] at the gain crossover [Hz] (inf / NaN where there is no crossover)."""

    loop: str
    gm_db: float
    pm_deg: float
    f_gm_hz: float
    f_pm_hz: float

    def to_json(self) -> dict[str, float]:
        return {"gm_db": self.gm_db, "pm_deg": self.pm_deg, "f_gm_hz": self.f_gm_hz,
                "f_pm_hz": self.f_pm_hz}


def loop_transfer(params: Mapping[str, float], loop: str, f_hz: np.ndarray) -> np.ndarray:
    """``L(j 2 pi f)`` of ``loop`` broken at its feedback (the other loop closed)."""
    return -linear_model(params, loop).response(f_hz, "v", "return")


def _refine(fun, a: float, b: float) -> float:
    """A root of ``fun`` in [a, b] (a sign change), by Brent's method on log f to 1e-13."""
    from scipy.optimize import brentq

    la, lb = math.log(a), math.log(b)
    fa, fb = fun(a), fun(b)
    if fa == 0.0 or fb == 0.0:
        return a if fa == 0.0 else b
    return math.exp(brentq(lambda u: fun(math.exp(u)), la, lb, xtol=1e-15, rtol=1e-14))


def margins(params: Mapping[str, float], loop: str, f_min: float = 1e-3, f_max: float = 1e5,
            n: int = 4000) -> Margins:
    """Gain and phase margins of ``loop`` ("position" or "speed"), from a dense log grid of
    ``L(j w)`` refined by bisection at each crossing; the smallest margins are reported when
    there are several crossings."""
    transfer = linear_model(params, loop).evaluator("v", "return")
    f = np.geomspace(f_min, f_max, n)
    Lf = -transfer(f)
    mag = np.abs(Lf)

    def one(x: float) -> complex:
        return complex(-transfer(np.array([x]))[0])

    pm, f_pm = math.inf, math.nan
    for k in np.flatnonzero(np.diff(np.sign(mag - 1.0)) != 0):
        fc = _refine(lambda x: abs(one(x)) - 1.0, f[k], f[k + 1])
        p = math.degrees(math.atan2(one(fc).imag, one(fc).real))
        margin = (p % 360.0) - 180.0  # 180 + angle, in (-180, 180]
        if abs(margin) < abs(pm):
            pm, f_pm = margin, fc
    gm, f_gm = math.inf, math.nan
    # phase crossovers: L crosses the negative real axis (Im L changes sign where Re L < 0)
    im = Lf.imag
    for k in np.flatnonzero(np.sign(im[:-1]) != np.sign(im[1:])):
        fc = _refine(lambda x: one(x).imag, f[k], f[k + 1])
        lc = one(fc)
        if lc.real >= 0:
            continue
        value = -20.0 * math.log10(abs(lc))
        if abs(value) < abs(gm):
            gm, f_gm = value, fc
    return Margins(loop, gm, pm, f_gm, f_pm)

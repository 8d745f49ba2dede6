"""An independent generator of rigid-axis records for the IDIM tests: scipy's ``solve_ivp`` on
the documented equation, never ema's simulator.

The axis: ``M q'' = F - f(q')`` with per-direction friction ``f = Fv+ q' + Fc+ + OF`` moving
forward, ``Fv- q' - Fc- + OF`` moving backward [N]. The force follows a three-sine reference
(0.3, 1.1 and 3.7 Hz; 50, 10 and 2 mm): the reference's inverse dynamics with the friction of
the axis' present direction, plus a stiff PD on the tracking error. Every velocity reversal is
an event of the integrator (DOP853, rtol 1e-10): the friction switches exactly there, and the
generator asserts that the axis goes on into the new direction (no sticking, which the law
cannot describe). The record: the position quantised like an encoder (``quantum_m``), the
force with white Gaussian noise (``force_noise_n``) from ``seed``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

AMPLITUDES_M = (0.05, 0.01, 0.002)  # the reference's sines [m]
FREQUENCIES_HZ = (0.3, 1.1, 3.7)  # [Hz]
PHASES_RAD = (0.0, 1.0, 2.0)  # [rad]
KP_N_PER_M = 4e4  # PD gains of the force on the tracking error [N/m]
KD_N_S_PER_M = 2e3  # [N*s/m]


@dataclass(frozen=True)
class AxisTruth:
    """The generating parameters, SI: M [kg], Fv+/Fv- [N*s/m], Fc+/Fc- [N] (magnitudes),
    OF [N]."""

    M: float = 95.0
    Fv_pos: float = 200.0
    Fv_neg: float = 200.0
    Fc_pos: float = 20.0
    Fc_neg: float = 20.0
    OF: float = -3.0

    def friction(self, v: float, s: float) -> float:
        """Friction plus offset [N] at velocity ``v`` [m/s] moving in direction ``s``."""
        if s > 0:
            return self.Fv_pos * v + self.Fc_pos + self.OF
        if s < 0:
            return self.Fv_neg * v - self.Fc_neg + self.OF
        return self.OF


@dataclass(frozen=True)
class AxisRecord:
    """A generated record at ``t_s``: measured ``q_m`` (quantised) and ``force_n`` (noisy);
    the true position, velocity and force."""

    t_s: np.ndarray
    q_m: np.ndarray
    force_n: np.ndarray
    q_true_m: np.ndarray
    v_true_m_s: np.ndarray
    force_true_n: np.ndarray


def _reference(t: float) -> tuple[float, float, float]:
    q = v = a = 0.0
    for amp, f, ph in zip(AMPLITUDES_M, FREQUENCIES_HZ, PHASES_RAD, strict=True):
        w = 2 * np.pi * f
        q += amp * np.sin(w * t + ph)
        v += amp * w * np.cos(w * t + ph)
        a -= amp * w**2 * np.sin(w * t + ph)
    return q, v, a


def rigid_axis_record(truth: AxisTruth, duration_s: float = 12.0, h_s: float = 1e-3,
                      force_noise_n: float = 5.0, quantum_m: float = 5e-8,
                      seed: int = 0) -> AxisRecord:
    """A record of the axis ``truth`` over ``duration_s`` sampled every ``h_s`` [s]."""
    def force(t: float, x: np.ndarray, s: float) -> float:
        qr, vr, ar = _reference(t)
        return (truth.M * ar + truth.friction(vr, s) + KP_N_PER_M * (qr - x[0])
                + KD_N_S_PER_M * (vr - x[1]))

    def rhs(t: float, x: np.ndarray, s: float) -> list[float]:
        return [x[1], (force(t, x, s) - truth.friction(x[1], s)) / truth.M]

    t_grid = np.arange(int(round(duration_s / h_s)) + 1) * h_s
    q0, v0, _ = _reference(0.0)
    x, t0, s = np.array([q0, v0]), 0.0, float(np.sign(v0))
    q, v, f = (np.empty_like(t_grid) for _ in range(3))
    while True:
        def reversal(t: float, x: np.ndarray, s: float) -> float:
            return x[1]
        reversal.terminal, reversal.direction = True, -s
        sol = solve_ivp(rhs, (t0, t_grid[-1]), x, args=(s,), method="DOP853", rtol=1e-10,
                        atol=1e-12, events=reversal, dense_output=True)
        here = (t_grid >= t0) & (t_grid <= sol.t[-1])
        if here.any():
            X = sol.sol(t_grid[here])
            q[here], v[here] = X
            f[here] = [force(tt, X[:, i], s) for i, tt in enumerate(t_grid[here])]
        if sol.status == 0:
            break
        x, t0, s = sol.y[:, -1].copy(), sol.t[-1], -s
        x[1] = 0.0
        acc = (force(t0, x, s) - truth.friction(0.0, s)) / truth.M
        assert acc * s > 0, f"the axis sticks at t = {t0:.4f} s; the generator cannot go on"
    rng = np.random.default_rng(seed)
    q_meas = np.round(q / quantum_m) * quantum_m if quantum_m > 0 else q.copy()
    return AxisRecord(t_grid, q_meas, f + force_noise_n * rng.standard_normal(f.size), q, v, f)

"""The drive: an armature (voltage in, current limit) or a current/force amplifier (numba).

Two drives turn the controller's command ``u`` (after the amplifier's dead zone, ``u_amp``)
into the torque on the motor shaft::

    armature   L*di/dt = u_amp - R*i - Ke*w_m   (model.plant.armature_rate_nb)
               T_m = Kt*i                                              [N*m, motor shaft]
    amplifier  f* = SAT(g*u_amp, f_max)        (the force the axis receives, load side)
               tau_a*df/dt = f* - f            (bandwidth 1/(2*pi*tau_a); tau_a = 0: f = f*)
               T_m = f/m                                               [N*m, motor shaft]

The amplifier's gain ``g`` is stated *referred to the load* (N/V on a translational axis, N*m/V
on a rotary one: what the axis receives per unit of command, the transmission included, as a
current amplifier and the motor's torque constant together give it and as benchmarks such as
EMPS publish it); on a rigid axis the force at the load is ``f`` itself.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ema_cli._numba import njit
from ema_cli.model.elements import saturate_nb


@njit(cache=True, forceinline=True, error_model="numpy")
def amplifier_demand_nb(u_amp, amp_gain, amp_limit):
    """The force (torque) the amplifier asks for, load side: ``SAT(g*u_amp, f_max)``."""
    return saturate_nb(amp_gain * u_amp, amp_limit)


@njit(cache=True, forceinline=True, error_model="numpy")
def amplifier_rate_nb(f_amp, u_amp, amp_gain, amp_limit, inv_amp_tau, amp_bw):
    """df/dt of the amplifier's first-order lag [N/s or N*m/s, load side]:
    ``(SAT(g*u_amp, f_max) - f)/tau_a`` (0 without a bandwidth: f is then algebraic)."""
    return ((amplifier_demand_nb(u_amp, amp_gain, amp_limit) - f_amp) * inv_amp_tau
            if amp_bw else 0.0)


@njit(cache=True, forceinline=True, error_model="numpy")
def amplifier_output_nb(f_amp, u_amp, amp_gain, amp_limit, amp_bw):
    """The amplifier's output force (torque), load side: the lag's state ``f`` with a
    bandwidth, else the demand itself."""
    return f_amp if amp_bw else amplifier_demand_nb(u_amp, amp_gain, amp_limit)


def torque_envelope(p: Mapping[str, float], w_m: np.ndarray, t_m: np.ndarray) -> np.ndarray:
    """The motor torque the drive can give at motor speed ``w_m`` [rad/s] in the quadrant of
    ``t_m`` [N*m] (its magnitude): an armature ``min(Kt*I_max, Kt*(V_max -+ Ke*|w_m|)/R)``
    (``-`` motoring, ``T*w >= 0``; ``+`` braking: the back-EMF helps; V_max the speed PI's
    voltage limit ``sat2``, I_max the current limit ``sat3``); an amplifier its output limit
    over the ratio."""
    w = np.abs(np.asarray(w_m, dtype=float))
    if p["drive"] == 1.0:
        return np.full(w.shape, p["amp_limit"] / p["m"])
    motoring = np.asarray(t_m) * np.asarray(w_m) >= 0.0
    volt = p["Kt"] * (p["sat2"] + np.where(motoring, -1.0, 1.0) * p["Ke"] * w) / p["R"]
    return np.maximum(np.minimum(p["Kt"] * p["sat3"], volt), 0.0)

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

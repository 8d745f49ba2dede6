"""The plant: armature with current limit, motor rotor, load with its external torque (numba).

States (``STATES``, SI): ``x = [theta_m, w_m, i, theta_L, w_L, z, xI]``::

    armature   L*di/dt    = u_amp - R*i - Ke*w_m       (0 while |i| >= sat3 and pushing outward)
    motor      Jm*dw_m/dt = Kt*i - bm*w_m - T/m - Tf
    load       JL*dw_L/dt = T - bL*w_L + T_load
    external   T_load     = T_const + T_profile(t) - k_h*theta_L

``T`` is the shaft torque (``transmission``), ``Tf`` the LuGre friction (``lugre``), ``z`` the
bristle state and ``xI`` the speed-PI integral (``controller``). ``T_load`` is the external
torque applied to the load (hinge moment, disturbance), positive in the direction of positive
``theta_L``; in steady state the shaft carries ``-T_load``. Reciprocals (``inv_L = 1/L`` ...)
are passed in because divisions are the slowest operations on the integrator's critical path.
"""

from __future__ import annotations

from dataclasses import dataclass

from ema_cli._numba import njit


@dataclass(frozen=True)
class State:
    """One state of the model: name, SI unit, meaning."""

    name: str
    unit: str
    description: str


STATES: tuple[State, ...] = (
    State("theta_m", "rad", "motor angle"),
    State("w_m", "rad/s", "motor speed"),
    State("i", "A", "armature current"),
    State("theta_L", "rad", "load angle"),
    State("w_L", "rad/s", "load speed"),
    State("z", "rad", "LuGre bristle deflection"),
    State("xI", "rad", "speed-PI integral of the speed error (motor side)"),
)
STATE_INDEX: dict[str, int] = {s.name: k for k, s in enumerate(STATES)}
N_STATES = len(STATES)


@njit(cache=True, forceinline=True, error_model="numpy")
def armature_rate_nb(i, w_m, u_amp, r, inv_l, ke, sat3):
    """di/dt [A/s] = (u_amp - R*i - Ke*w_m)/L, held at 0 while ``|i| >= sat3`` [A] and the
    current would grow outward (the drive's current limit; sat3 = inf: none)."""
    di = (u_amp - r * i - ke * w_m) * inv_l
    return 0.0 if (abs(i) >= sat3 and di * i > 0.0) else di


@njit(cache=True, forceinline=True, error_model="numpy")
def motor_accel_nb(i, w_m, t_shaft, t_fric, kt, bm, inv_m, inv_jm):
    """dw_m/dt [rad/s^2] = (Kt*i - bm*w_m - T/m - Tf)/Jm (T load side, Tf at the motor)."""
    return (kt * i - bm * w_m - t_shaft * inv_m - t_fric) * inv_jm


@njit(cache=True, forceinline=True, error_model="numpy")
def load_accel_nb(w_l, t_shaft, t_load, bl, inv_jl):
    """dw_L/dt [rad/s^2] = (T - bL*w_L + T_load)/JL."""
    return (t_shaft - bl * w_l + t_load) * inv_jl


@njit(cache=True, forceinline=True, error_model="numpy")
def load_torque_nb(th_l, t_const, t_profile, k_h):
    """External torque on the load [N*m]: ``T_const + T_profile(t) - k_h*theta_L``."""
    return t_const + t_profile - k_h * th_l

"""The plant: armature with current limit, motor rotor, transmission, load; compliant or rigid.

Compliant (two masses; the paper's EMA), SI, load side in the axis's units (rad or m)::

    armature   L*di/dt    = u_amp - R*i - Ke*w_m       (0 while |i| >= sat3 and pushing outward)
    motor      Jm*dw_m/dt = T_d - bm*w_m - T/m - Tf_m
    load       JL*dw_L/dt = T - bL*w_L + T_ext - Ff_L
    external   T_ext      = (T_const - offset) + T_profile(t) - k_h*theta_L

``T_d`` is the drive's torque on the motor (``Kt*i``, or the amplifier's, ``model.drive``),
``T`` the shaft torque (``model.transmission``), ``Tf_m`` and ``Ff_L`` the friction at the motor
and at the load (``model.lugre``, ``model.friction``). ``T_ext`` is the external torque applied
to the load (hinge moment, disturbance, the constant offset), positive along +theta_L.

Rigid (one mass, in load coordinates; motor angle and speed are ``m`` times the load's)::

    (JL + m^2*Jm)*dw_L/dt = m*(T_d - bm*w_m - Tf_m) - bL*w_L + T_ext - Ff_L,   w_m = m*w_L

A site with a static friction law that sticks holds its speed at exactly 0 (its rate is 0 here;
``model.friction`` says when it sticks). Reciprocals (``inv_L = 1/L`` ...) are passed in because
divisions are the slowest operations on the integrator's critical path.

The ``*_rate_nb`` functions are the state equations of ``model.states.STATES``: the kernel binds
their arguments by name, and holds a state (rate 0) under its row's ``hold`` conditions.
"""

from __future__ import annotations

from ema_cli._numba import njit
from ema_cli.model.controller import integral_rate_nb


@njit(cache=True, forceinline=True, error_model="numpy")
def armature_rate_nb(i, w_m, u_amp, r, inv_l, ke, sat3):
    """di/dt [A/s] = (u_amp - R*i - Ke*w_m)/L, held at 0 while ``|i| >= sat3`` [A] and the
    current would grow outward (the drive's current limit; sat3 = inf: none)."""
    di = (u_amp - r * i - ke * w_m) * inv_l
    return 0.0 if (abs(i) >= sat3 and di * i > 0.0) else di


@njit(cache=True, forceinline=True, error_model="numpy")
def motor_accel_nb(t_drive, w_m, t_shaft, t_fric, bm, inv_m, inv_jm):
    """dw_m/dt [rad/s^2] = (T_d - bm*w_m - T/m - Tf)/Jm (T load side, Tf at the motor)."""
    return (t_drive - bm * w_m - t_shaft * inv_m - t_fric) * inv_jm


@njit(cache=True, forceinline=True, error_model="numpy")
def load_accel_nb(w_l, t_shaft, t_load, bl, inv_jl):
    """dw_L/dt [rad/s^2] = (T - bL*w_L + T_ext)/JL."""
    return (t_shaft - bl * w_l + t_load) * inv_jl


@njit(cache=True, forceinline=True, error_model="numpy")
def load_torque_nb(th_l, t_const, t_profile, k_h):
    """External torque on the load [N*m]: ``T_const + T_profile(t) - k_h*theta_L`` (the offset
    is folded into ``T_const`` by the caller)."""
    return t_const + t_profile - k_h * th_l


@njit(cache=True, forceinline=True, error_model="numpy")
def rigid_force_nb(t_drive, w_m, t_fric_m, w_l, t_load, f_fric_l, m, bm, bl):
    """The net force on a rigid axis, load side: ``m*(T_d - bm*w_m - Tf_m) - bL*w_L + T_ext -
    Ff_L`` (with a site that sticks, the friction there is 0 and this is the force it holds)."""
    return m * (t_drive - bm * w_m - t_fric_m) - bl * w_l + t_load - f_fric_l


# ---- the state equations (model.states.STATES: arguments bound by name) ---------------------

@njit(cache=True, forceinline=True, error_model="numpy")
def motor_angle_rate_nb(w_m):
    """d(theta_m)/dt = w_m."""
    return w_m


@njit(cache=True, forceinline=True, error_model="numpy")
def load_position_rate_nb(w_L):
    """d(theta_L)/dt = w_L."""
    return w_L


@njit(cache=True, forceinline=True, error_model="numpy")
def motor_speed_rate_nb(i, Kt, t_drive, w_m, t_shaft, t_fric_m, tf_b, visc, bm, inv_m, inv_Jm,
                        amp, static_m):
    """d(w_m)/dt (:func:`motor_accel_nb`). The armature's torque ``Kt*i`` and the LuGre friction
    ``Tb + sigma2*w_m`` are formed here, as the paper's kernel always formed them (which
    multiply-adds the compiler fuses depends on where an operation is: the paper's EMA stays bit
    for bit); the amplifier's torque and the static law's friction come from the algebra."""
    t_d = t_drive if amp else Kt * i
    t_f = t_fric_m if static_m else tf_b + visc * w_m
    return motor_accel_nb(t_d, w_m, t_shaft, t_f, bm, inv_m, inv_Jm)


@njit(cache=True, forceinline=True, error_model="numpy")
def current_rate_nb(i, w_m, u_amp, R, inv_L, Ke, sat3, th_w, th_r0, th_ra, thermal):
    """di/dt (:func:`armature_rate_nb`), with the thermal element's R(T) = ``th_r0 + th_ra*th_w``
    (``model.thermal``) when the variant has it."""
    r = th_r0 + th_ra * th_w if thermal else R
    return armature_rate_nb(i, w_m, u_amp, r, inv_L, Ke, sat3)


@njit(cache=True, forceinline=True, error_model="numpy")
def load_speed_rate_nb(w_L, theta_L, t_shaft, l_prof, t_const, k_h, bL, inv_JL, f_fric_L,
                       f_rigid, inv_Jtot, rigid, fric_L):
    """d(w_L)/dt: compliant :func:`load_accel_nb` (the external torque formed here, as the
    paper's kernel formed it) less the load friction, rigid ``f_rigid/(JL + m^2*Jm)``."""
    if rigid:
        return f_rigid * inv_Jtot
    t_load = load_torque_nb(theta_L, t_const, l_prof, k_h)
    if fric_L:
        return (t_shaft - bL * w_L + t_load - f_fric_L) * inv_JL
    return load_accel_nb(w_L, t_shaft, t_load, bL, inv_JL)


@njit(cache=True, forceinline=True, error_model="numpy")
def speed_integral_rate_nb(e_w, u_unsat, sat2, disc):
    """d(xI)/dt: the continuous speed PI's integral with clamping anti-windup
    (``model.controller.integral_rate_nb``); 0 when digital (advanced at the samples)."""
    return 0.0 if disc else integral_rate_nb(e_w, u_unsat, sat2)

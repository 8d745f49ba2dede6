"""The cascade controller: sensors, position P, speed PI with clamping anti-windup (numba).

::

    theta_meas = Q(DZ(theta_fb, d4), q_pos)       w_meas = Q(DZ(w_m, d3), q_speed)
    theta_fb = (1 - b)*theta_L + b*theta_m/m      b = fb_motor: 0 load sensor, 1 motor angle
    w*_L  = SAT(Kpp*(theta_ref - theta_meas), sat1)                 [rad/s, load side]
    e_w   = m*w*_L - w_meas                                         [rad/s, motor side]
    u_dem = SAT(Kps*e_w + Kis*xI, sat2)                             [V]
    dxI/dt = e_w, or 0 while SAT2 is active and e_w pushes further into the limit

DZ is the dead zone, SAT the saturation, Q the quantiser (``q = 0``: none), see ``elements``.
Continuous by default; with a sample time ``Ts`` the same equations are evaluated at the sample
instants and ``u_dem`` is held between them (zero-order hold), the integral advancing by forward
Euler, ``xI[k+1] = xI[k] + Ts*dxI/dt`` (:func:`integral_update_nb`).
"""

from __future__ import annotations

from ema_cli._numba import njit
from ema_cli.model.elements import dead_zone_nb, quantize_nb, saturate_nb


@njit(cache=True, forceinline=True, error_model="numpy")
def sensors_nb(th_l, w_m, d4, d3, q_pos, q_speed, inv_q_pos, inv_q_speed, th_mm=0.0, fb=0.0):
    """Measured position [rad] and motor speed [rad/s]: the position fed back is the load angle
    ``th_l``, the motor angle over the ratio ``th_mm``, or the blend ``(1-fb)*th_l + fb*th_mm``;
    sensor dead zones (half-widths ``d4`` [rad], ``d3`` [rad/s]), then quantisers (quanta
    ``q_pos`` [rad], ``q_speed`` [rad/s], 0: none, with their reciprocals)."""
    th_fb = th_l + fb * (th_mm - th_l) if fb != 0.0 else th_l
    return (quantize_nb(dead_zone_nb(th_fb, d4), q_pos, inv_q_pos),
            quantize_nb(dead_zone_nb(w_m, d3), q_speed, inv_q_speed))


@njit(cache=True, forceinline=True, error_model="numpy")
def cascade_nb(r, th_meas, w_meas, x_i, m, kpp, kps, kis, sat1, sat2):
    """Position P and speed PI -> ``(e_w, u_unsat, u_dem)`` [rad/s, V, V].

    ``r`` reference [rad], ``th_meas`` [rad], ``w_meas`` [rad/s, motor], ``x_i`` speed-error
    integral [rad], ``m`` gear ratio, ``kpp`` [1/s], ``kps`` [V*s/rad], ``kis`` [V/rad],
    ``sat1`` [rad/s, load], ``sat2`` [V] (inf: no limit).
    """
    wl_star = saturate_nb(kpp * (r - th_meas), sat1)
    e_w = m * wl_star - w_meas
    u_unsat = kps * e_w + kis * x_i
    return e_w, u_unsat, saturate_nb(u_unsat, sat2)


@njit(cache=True, forceinline=True, error_model="numpy")
def integral_rate_nb(e_w, u_unsat, sat2):
    """dxI/dt [rad/s] with clamping anti-windup: 0 while ``|u_unsat| > sat2`` and ``e_w`` has
    the sign of ``u_unsat`` (it would push further into the limit), else ``e_w``."""
    return 0.0 if (abs(u_unsat) > sat2 and e_w * u_unsat > 0.0) else e_w


@njit(cache=True, forceinline=True, error_model="numpy")
def integral_update_nb(x_i, e_w, u_unsat, sat2, ts):
    """Discrete PI integral ``xI[k+1] = xI[k] + Ts*dxI/dt`` (forward Euler, same anti-windup)."""
    return x_i + ts * integral_rate_nb(e_w, u_unsat, sat2)

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

import math

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


@njit(cache=True, forceinline=True, error_model="numpy")
def smooth_sign_nb(x, band):
    """``sign(x)`` ramped linearly over ``|x| < band`` (``band`` > 0)."""
    return min(max(x / band, -1.0), 1.0)


@njit(cache=True, forceinline=True, error_model="numpy")
def deadzone_inverse_nb(u, d_est, band):
    """Voltage sent to the amplifier [V]: the demand ``u`` plus the estimated dead zone
    ``d_est`` [V] in its direction, ramped over ``|u| < band`` [V] against chattering (0: off).
    With ``d_est`` equal to the true dead zone the amplifier outputs ``u`` for ``|u| >= band``."""
    return u + d_est * smooth_sign_nb(u, band) if d_est > 0.0 else u


@njit(cache=True, forceinline=True, error_model="numpy")
def friction_ff_nb(w_cmd, w_meas, fc, fs, vs, delta, sig2, band):
    """Friction compensation torque [N*m]: the estimated Coulomb-Stribeck part
    ``(Fc + (Fs - Fc) exp(-|w/vs|^delta)) sign(w)`` at the motor speed command ``w_cmd``
    [rad/s] (feed-forward: it cannot destabilise the loop), its sign ramped over
    ``|w| < band`` [rad/s] (a Stribeck peak only when Fs > Fc), plus the estimated viscous part
    ``sigma2 * w_meas`` on the measured motor speed [rad/s] (it cancels the viscous friction,
    so the loop keeps the margins of the frictionless actuator)."""
    g = fc
    if fs > fc:
        g += (fs - fc) * math.exp(-(abs(w_cmd / vs) ** delta))
    return g * smooth_sign_nb(w_cmd, band) + sig2 * w_meas


@njit(cache=True, forceinline=True, error_model="numpy")
def notch_gain_nb(f_hz, depth, zeta):
    """(w [rad/s], c) of the notch ``(s^2 + 2 depth zeta w s + w^2)/(s^2 + 2 zeta w s + w^2)``
    written as ``y = u + c*x2`` with ``x1' = x2``, ``x2' = -w^2 x1 - 2 zeta w x2 + u``."""
    w = 2.0 * math.pi * f_hz
    return w, 2.0 * (depth - 1.0) * zeta * w


@njit(cache=True, forceinline=True, error_model="numpy")
def notch_update_nb(x1, x2, u, w, zeta, h):
    """The notch states one step ``h`` [s] on, the input ``u`` held: trapezoidal (Tustin)."""
    a = 0.5 * h
    # (I - A a) x+ = (I + A a) x + B h u, A = [[0, 1], [-w^2, -2 zeta w]], B = [0, 1]
    r1 = x1 + a * x2
    r2 = x2 + a * (-w * w * x1 - 2.0 * zeta * w * x2) + h * u
    m11, m12 = 1.0, -a
    m21, m22 = a * w * w, 1.0 + 2.0 * a * zeta * w
    det = m11 * m22 - m12 * m21
    return (r1 * m22 - m12 * r2) / det, (m11 * r2 - m21 * r1) / det

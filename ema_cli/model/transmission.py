"""The gear train's shaft torque: stiffness, backlash dead band and damping (paper Eq. 2).

One function, :func:`shaft_torque_nb`, used by the simulator, the identification and the figures.
"""

from __future__ import annotations

import math

import numpy as np

from ema_cli._numba import njit
from ema_cli.model.elements import dead_zone_nb

_INF = math.inf

FORMS = ("contact", "paper")
"""Damping forms: ``contact`` (the default; T = 0 in the gap and never pulls) or ``paper``."""


def inverse_tau(tau: float) -> float:
    """``1/tau`` [1/s] for :func:`shaft_torque_nb`; ``inf`` for ``tau = 0`` (the jump form)."""
    return 1.0 / tau if tau > 0.0 else math.inf


def hc_gain(hc: float, pen_ref: float) -> float:
    """``h/contact_pen`` [1/rad] for :func:`shaft_torque_nb` (0 when ``h = 0``)."""
    return hc / pen_ref if hc > 0.0 else 0.0


@njit(cache=True, forceinline=True, error_model="numpy")
def shaft_torque_nb(kL, alpha, c, contact, inv_tau, hc, hck, dth, dw, hw):
    """Transmission torque T [N*m, load side] for deflection ``dth`` [rad] and rate ``dw`` [rad/s].

    ``dth = theta_m/m - theta_L``, ``dw = w_m/m - w_L`` (load side); ``kL`` [N*m/rad],
    ``alpha`` half backlash [rad], ``c`` [N*m*s/rad], ``contact`` True for the contact form,
    ``inv_tau`` = 1/tau [1/s] of the contact form's damping ramp-in time ``tau``
    (:func:`inverse_tau`; ``inf``: tau = 0), ``hc`` the Hunt-Crossley share ``h`` of the
    contact form's damping [-] and ``hck = h/contact_pen`` [1/rad] (:func:`hc_gain`)::

        paper form:    T = kL*DZ(dth, alpha) + c*dw                       (paper Eq. 2)
        contact form:  T = 0 inside the gap (|dth| <= alpha); in contact, with the penetration
                       pen = |dth| - alpha > 0,
                           T = kL*DZ(dth, alpha) + c*g*clip(dw, -pen/tau, +pen/tau),
                       g = (1 - h) + h*pen/contact_pen   (1 with h = 0),
                       clamped so that it pushes but never pulls: max(T, 0) if dth > alpha,
                       min(T, 0) if dth < -alpha.

    The damping torque is at most ``(c/tau)*pen``: it vanishes at first touch and reaches
    ``c*dw`` once the penetration exceeds ``|dw|*tau``, i.e. about ``tau`` after an impact at
    any closing speed (a damper acting through a contact compliance of stiffness c/tau). So
    the torque is continuous at contact and the trajectory is continuous in the parameters.
    ``tau = 0`` (``inv_tau = inf``) is the jump form: T jumps by c*dw at contact. The
    Hunt-Crossley share (``h`` > 0) makes the damping grow with the penetration, 0 at first
    touch: with ``h = 1`` and ``tau = 0``, ``T = kL*pen*(1 + lam*dpen/dt)``, ``lam =
    c/(kL*contact_pen)`` (Hunt and Crossley 1975, linear spring). With
    ``alpha = 0`` both forms are the permanent-contact shaft ``T = kL*dth + c*dw`` (no tau).

    ``hw`` [s] (the fixed-step simulator passes ``dt/2``; 0: the exact law) regularises the
    jump form for a fixed-step integrator: on a *closing* contact the damping's weight rises
    linearly from 0 to 1 across the penetration band ``|pen| <= half = hw*|dw|`` (at most
    ``alpha/2``), i.e. over the one step centred on the touch instead of at the first RK4
    stage that finds the contact. The torque is then continuous in the state, so the simulated
    trajectory is continuous in the parameters (an impact moving across the step grid no
    longer moves the output by a step's worth of damping), and the impulse of the damping
    differs from the exact jump's by O(dt^2) instead of O(dt) (the ramp minus the step is odd
    about the touch). Inside the band's lower half the contact pushes by its damping alone (the
    spring starts at pen = 0); separation (opening) is untouched. With ``tau > 0`` or
    ``hw = 0`` every value is the unregularised law's, bit for bit.
    Branch-free (selects), so it vectorises.
    """
    spring = kL * dead_zone_nb(dth, alpha)
    t = spring + c * dw
    pen = abs(dth) - alpha
    jump = inv_tau == _INF
    # the jump form's closing band [-half, +half] of penetration (0: the exact law)
    closing = dw > 0.0 if dth > 0.0 else dw < 0.0
    half = min(hw * abs(dw), 0.5 * alpha) if (jump and closing) else 0.0
    wgt = 1.0 if pen >= half else (0.0 if pen <= -half else (pen + half) / (half + half))
    # tau > 0: in contact pen > 0 (dth > alpha implies dth - alpha > 0 in floating point);
    # outside contact the limit is not used
    lim = pen * inv_tau
    g = (1.0 - hc) + hck * max(pen, 0.0)
    damp = c * g * wgt * dw if jump else c * g * min(max(dw, -lim), lim)
    tc = spring + damp
    clamped = (max(tc, 0.0) if dth > alpha - half
               else (min(tc, 0.0) if dth < -(alpha - half) else 0.0))
    return clamped if (contact and alpha > 0.0) else t


@njit(cache=True, error_model="numpy", entry=True)
def shaft_torque_array_nb(kL, alpha, c, contact, inv_tau, hc, hck, dth, dw, out):
    """:func:`shaft_torque_nb` (the exact law, ``hw = 0``) over arrays ``dth[n]``, ``dw[n]``
    into ``out[n]`` [N*m]."""
    for i in range(dth.shape[0]):
        out[i] = shaft_torque_nb(kL, alpha, c, contact, inv_tau, hc, hck, dth[i], dw[i], 0.0)


def shaft_torque(dth: np.ndarray, dw: np.ndarray, kL: float, alpha: float, c: float,
                 form: str, tau: float = 0.0, hc: float = 0.0,
                 pen_ref: float = 1.0e-3) -> np.ndarray:
    """Transmission torque [N*m] for arrays of deflection [rad] and rate [rad/s]; ``form`` is
    ``contact`` or ``paper``, ``tau`` [s] the contact form's damping ramp-in time (0: none,
    the jump form), ``hc`` the Hunt-Crossley share of the damping [-] and ``pen_ref`` its
    reference penetration [rad] (see :func:`shaft_torque_nb`)."""
    if form not in FORMS:
        raise ValueError(f"form must be one of {FORMS}, got {form!r}")
    if not tau >= 0.0:
        raise ValueError(f"tau must be >= 0, got {tau!r}")
    dth = np.ascontiguousarray(dth, dtype=np.float64)
    dw = np.ascontiguousarray(dw, dtype=np.float64)
    out = np.empty_like(dth)
    shaft_torque_array_nb(float(kL), float(alpha), float(c), form == "contact",
                          inverse_tau(float(tau)), float(hc), hc_gain(float(hc), float(pen_ref)),
                          dth.ravel(), dw.ravel(), out.ravel())
    return out


@njit(cache=True, forceinline=True, error_model="numpy")
def preload_torque_nb(preload, alpha, dth):
    """The anti-backlash preload's torque [N*m, load side] at deflection ``dth`` [rad]: a spring
    preloaded to ``preload`` [N*m] bridges the gap of half width ``alpha`` [rad] > 0, so inside
    it the torque rises linearly from -preload to +preload, and in contact the preload adds to
    the teeth's torque (:func:`shaft_torque_nb`)::

        T_pre = preload * clip(dth/alpha, -1, +1)

    The torque-twist curve is then continuous: slope preload/alpha through the gap, then
    kL + the same offset. ``preload = 0``: nothing (the plain dead band)."""
    return preload * min(max(dth / alpha, -1.0), 1.0)


@njit(cache=True, forceinline=True, error_model="numpy")
def friction_rate_nb(w_m, w_L, inv_m, f_t, Fc_t, sigma_t, trans):
    """d f_t/dt of the transmission's friction [N*m/s, load side]: a Dahl element in parallel
    with the shaft, driven by the twist rate ``dw = w_m/m - w_L`` [rad/s]::

        df_t/dt = sigma_t * (dw - |dw| * f_t / Fc_t)

    ``f_t`` tends to ``+-Fc_t`` [N*m] while the twist grows (shrinks): the loaded and unloaded
    branches of a torque-twist loop lie ``2*Fc_t`` apart, joined after each reversal by an
    exponential of twist scale ``Fc_t/sigma_t`` [rad] (``sigma_t`` [N*m/rad]: the slope right
    after a reversal; Dahl 1968, rate-independent). 0 when the variant has no transmission
    friction (``trans`` False) or ``Fc_t = 0``."""
    if not trans or Fc_t <= 0.0:
        return 0.0
    dw = w_m * inv_m - w_L
    return sigma_t * (dw - abs(dw) * f_t / Fc_t)


def dahl_path(dth: np.ndarray, Fc_t: float, sigma_t: float, f0: float = 0.0) -> np.ndarray:
    """The Dahl friction torque [N*m] along a sampled twist path ``dth[n]`` [rad], exactly for
    a twist monotonic between samples (the element is rate-independent, so the path is all it
    needs): after an increment ``d`` of sign ``s``,
    ``f <- s*Fc_t + (f - s*Fc_t) * exp(-sigma_t*|d|/Fc_t)``. ``f0``: the torque at ``dth[0]``."""
    dth = np.asarray(dth, dtype=np.float64)
    out = np.empty_like(dth)
    if dth.size == 0:
        return out
    return _dahl_path_nb(dth, float(Fc_t), float(sigma_t), float(f0), out)


@njit(cache=True, error_model="numpy", entry=True)
def _dahl_path_nb(dth, Fc_t, sigma_t, f0, out):
    f = f0
    out[0] = f
    if Fc_t <= 0.0:
        out[:] = 0.0
        return out
    for k in range(1, dth.shape[0]):
        d = dth[k] - dth[k - 1]
        if d != 0.0:
            s = 1.0 if d > 0.0 else -1.0
            f = s * Fc_t + (f - s * Fc_t) * math.exp(-sigma_t * abs(d) / Fc_t)
        out[k] = f
    return out

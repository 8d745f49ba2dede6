"""The gear train's shaft torque: stiffness, backlash dead band and damping (paper Eq. 2).

One function, :func:`shaft_torque_nb`, used by the simulator, the identification and the figures.
"""

from __future__ import annotations

import numpy as np

from ema_cli._numba import njit
from ema_cli.model.elements import dead_zone_nb

FORMS = ("contact", "paper")
"""Damping forms: ``contact`` (the default; T = 0 in the gap and never pulls) or ``paper``."""


@njit(cache=True, forceinline=True, error_model="numpy")
def shaft_torque_nb(kL, alpha, c, contact, dth, dw):
    """Transmission torque T [N*m, load side] for deflection ``dth`` [rad] and rate ``dw`` [rad/s].

    ``dth = theta_m/m - theta_L``, ``dw = w_m/m - w_L`` (load side); ``kL`` [N*m/rad],
    ``alpha`` half backlash [rad], ``c`` [N*m*s/rad], ``contact`` True for the contact form::

        paper form:    T = kL*DZ(dth, alpha) + c*dw                       (paper Eq. 2)
        contact form:  T = 0 inside the gap (|dth| <= alpha); in contact the Eq. 2 torque,
                       clamped so that it pushes but never pulls: max(T, 0) if dth > alpha,
                       min(T, 0) if dth < -alpha.

    With ``alpha = 0`` both forms are the permanent-contact shaft ``T = kL*dth + c*dw``.
    Branch-free (selects), so it vectorises.
    """
    t = kL * dead_zone_nb(dth, alpha) + c * dw
    clamped = max(t, 0.0) if dth > alpha else (min(t, 0.0) if dth < -alpha else 0.0)
    return clamped if (contact and alpha > 0.0) else t


@njit(cache=True, error_model="numpy")
def shaft_torque_array_nb(kL, alpha, c, contact, dth, dw, out):
    """:func:`shaft_torque_nb` over arrays ``dth[n]``, ``dw[n]`` into ``out[n]`` [N*m]."""
    for i in range(dth.shape[0]):
        out[i] = shaft_torque_nb(kL, alpha, c, contact, dth[i], dw[i])


def shaft_torque(dth: np.ndarray, dw: np.ndarray, kL: float, alpha: float, c: float,
                 form: str) -> np.ndarray:
    """Transmission torque [N*m] for arrays of deflection [rad] and rate [rad/s]; ``form`` is
    ``contact`` or ``paper`` (see :func:`shaft_torque_nb`)."""
    if form not in FORMS:
        raise ValueError(f"form must be one of {FORMS}, got {form!r}")
    dth = np.ascontiguousarray(dth, dtype=np.float64)
    dw = np.ascontiguousarray(dw, dtype=np.float64)
    out = np.empty_like(dth)
    shaft_torque_array_nb(float(kL), float(alpha), float(c), form == "contact", dth.ravel(),
                          dw.ravel(), out.ravel())
    return out

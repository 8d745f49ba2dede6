"""LuGre friction at the motor shaft: Stribeck curve, exact bristle update, friction torque.

::

    g(w)   = Fc + (Fs - Fc)*exp(-|w/vs|**delta)                  [N*m]
    dz/dt  = w - sigma0*|w|/g(w)*z                               [rad/s]
    Tf     = sigma0*z + sigma1*dz/dt + sigma2*w                  [N*m]

Notes: the bristle state is stiff (its eigenvalue ``-a = -sigma0*|w|/g(w)`` reaches -3e5 1/s at
20 deg step speeds), so a fixed-step solver advances it with the exact solution for ``w`` frozen
over the step (:func:`bristle_step_nb`). Branch-free and vectorisable (``vmath``).
"""

from __future__ import annotations

from ema_cli._numba import njit
from ema_cli.model.vmath import exp_nb, expm1_nb, pow_nb

TINY_DECAY = 1.0e-9  # below this a*dt the bristle update uses its first-order limit [-]


@njit(cache=True, forceinline=True, error_model="numpy")
def stribeck_nb(w, fc, fs, vs, delta):
    """g(w) = Fc + (Fs - Fc)*exp(-|w/vs|**delta) [N*m] at speed ``w`` [rad/s]."""
    return fc + (fs - fc) * exp_nb(-pow_nb(abs(w / vs), delta))


@njit(cache=True, forceinline=True, error_model="numpy")
def bristle_step_nb(z, w, dt, fc, fs, vs, delta, sigma0, sigma1):
    """Advance the bristle state ``z`` [rad] over ``dt`` [s] at frozen speed ``w`` [rad/s].

    Exact for frozen w: ``z+ = z_ss + (z - z_ss)*exp(-a*dt)``, ``a = sigma0*|w|/g(w)``,
    ``z_ss = w/a``. Returns ``(z+, Tb)`` with the exact step averages of the bristle torque
    ``Tb = sigma0*mean(z) + sigma1*(z+ - z)/dt`` [N*m], to be held over the step (the viscous part
    ``sigma2*w`` is added by the caller at each stage). Below ``a*dt = 1e-9`` the first-order
    limit ``z+ = z + (w - a*z)*dt`` is used (no division by a ~ 0).
    """
    a = sigma0 * abs(w) / stribeck_nb(w, fc, fs, vs, delta)
    ad = a * dt
    zss = w / a
    decay = -expm1_nb(-ad)  # 1 - exp(-a*dt)
    z_new = zss + (z - zss) * (1.0 - decay)
    z_mean = zss + (z - zss) * decay / ad
    z_lin = z + (w - a * z) * dt
    tiny = ad < TINY_DECAY
    z_new = z_lin if tiny else z_new
    z_mean = 0.5 * (z + z_lin) if tiny else z_mean
    return z_new, sigma0 * z_mean + sigma1 * (z_new - z) / dt


@njit(cache=True, forceinline=True, error_model="numpy")
def steady_friction_nb(w, fc, fs, vs, delta, sigma2):
    """Steady-state LuGre friction torque at constant speed ``w`` [rad/s]:
    ``sign(w)*g(w) + sigma2*w`` [N*m] (the static friction curve; 0 at w = 0)."""
    s = 1.0 if w > 0.0 else (-1.0 if w < 0.0 else 0.0)
    return s * stribeck_nb(w, fc, fs, vs, delta) + sigma2 * w

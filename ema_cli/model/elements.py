"""Static nonlinear elements: dead zone, saturation, quantiser (numba, branch-free).

Each is a scalar function compiled inline into the kernels; the ``min``/``max``/select forms
let the compiler vectorise them across the batch lanes. Units are those of the signal.
"""

from __future__ import annotations

import numpy as np

from ema_cli._numba import njit


@njit(cache=True, forceinline=True, error_model="numpy")
def dead_zone_nb(u, d):
    """Dead zone ``DZ(u, d) = sign(u)*max(|u| - d, 0)`` = ``u - clip(u, -d, d)``.

    ``d >= 0`` is the half-width in the unit of ``u``; ``d = 0`` is the identity (exactly), as in
    Simulink's Dead Zone block with limits ``-d, +d``.
    """
    return u - min(max(u, -d), d)


@njit(cache=True, forceinline=True, error_model="numpy")
def saturate_nb(u, lim):
    """Saturation ``SAT(u, lim) = clip(u, -lim, +lim)``; ``lim = inf`` is no limit."""
    return min(max(u, -lim), lim)


@njit(cache=True, forceinline=True, error_model="numpy")
def quantize_nb(u, q, inv_q):
    """Uniform quantiser ``q*floor(u/q + 1/2)`` (round half up) with quantum ``q`` and its
    reciprocal ``inv_q = 1/q`` (a multiplication is much cheaper than a division in the
    integrator's inner loop); ``q = 0`` passes ``u`` unchanged. Models an encoder
    (q = 2*pi/counts) or a speed resolution."""
    y = q * np.floor(u * inv_q + 0.5)
    return y if q > 0.0 else u

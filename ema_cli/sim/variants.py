"""Kernel variants: which compiled version of the kernel each configuration needs.

A configuration's *variant* (``model.actuator``: friction at the motor and at the load, the
paper cascade's extras, a rigid axis, an amplifier and its bandwidth, the controller, an input
signal) is read from its parameter row; the runner groups a batch's rows by variant and calls
each variant's compiled entry point for its rows (a variant is compiled the first time a batch
needs it). Variants with a sampled controller, a quantiser, a compensator, static friction or
another controller run one lane at a time: their branches do not vectorise.
"""

from __future__ import annotations

import numpy as np

from ema_cli._numba import njit
from ema_cli.model.actuator import (
    B_AMP,
    B_AMP_BW,
    B_CTRL,
    B_EXT,
    B_EXTRAS,
    B_FRIC_L,
    B_RIGID,
    B_THERMAL,
    B_TRANS,
    CTRL_NONE,
    FRIC_LUGRE1,
    FRIC_STATIC,
    LFRIC_STATIC,
)
from ema_cli.sim.layout import R

LANES = 16  # configurations advanced together in a chunk (see make bench) [lanes]


@njit(cache=True, forceinline=True, error_model="numpy")
def _lane_variant(W, j):
    """The variant code lane ``j`` of ``W`` (rows: model.params order first) needs alone
    (``model.actuator``): the one definition :func:`variant_codes` and :func:`variant_order`
    use. Extras: the digital controller, a quantiser or a compensator (any controller's
    sampling); the locked motor runs in every variant."""
    fric = W[R.friction, j]
    fric_m = (0 if fric == 0.0 else (3 if fric == 2.0 else (1 if W[R.delta, j] == 1.0
                                                             else 2)))
    extras = (W[R.Ts, j] > 0.0 or W[R.q_pos, j] > 0.0 or W[R.q_speed, j] > 0.0
              or W[R.dzi_v, j] > 0.0 or W[R.ff_fc, j] > 0.0
              or W[R.ff_sigma2, j] > 0.0 or W[R.notch_hz, j] > 0.0
              or W[R.ff_sigma0, j] > 0.0)
    amp = W[R.drive, j] == 1.0
    ctrl = int(W[R.ctrl, j])
    fric_l = int(W[R.friction_L, j])
    ext = ctrl == CTRL_NONE or W[R.dist_out, j] != 0.0
    trans = W[R.Fc_t, j] > 0.0 or W[R.preload, j] > 0.0
    return (fric_m | (int(extras) << B_EXTRAS) | (int(W[R.rigid, j] != 0.0) << B_RIGID)
            | (int(amp) << B_AMP) | (int(amp and W[R.amp_tau, j] > 0.0) << B_AMP_BW)
            | (fric_l << B_FRIC_L) | (ctrl << B_CTRL) | (int(ext) << B_EXT)
            | (int(trans) << B_TRANS)
            | (int(W[R.thermal, j] != 0.0) << B_THERMAL))


@njit(cache=True, error_model="numpy", entry=True)
def _variant_codes_nb(PT):
    """Per configuration (column of ``PT[N_PARAMS, n_cases]``), the variant it needs alone."""
    out = np.empty(PT.shape[1], dtype=np.int64)
    for j in range(PT.shape[1]):
        out[j] = _lane_variant(PT, j)
    return out


def variant_codes(P: np.ndarray) -> np.ndarray:
    """Per row of ``P[n_cases, N_PARAMS]`` the kernel variant it needs alone (a code of
    ``model.actuator``; the paper's EMA: ``fric + 4*extras``, fric 0 no friction, 1 LuGre with
    the Stribeck exponent 1, 2 any other)."""
    return _variant_codes_nb(np.ascontiguousarray(P.T))


def variant_order(P: np.ndarray) -> np.ndarray:
    """The rows of ``P[n_cases, N_PARAMS]`` sorted (stably) by the kernel variant they need
    (cheapest first), so that the rows of one variant are contiguous: the permutation
    ``order`` (run ``P[order]``)."""
    return np.argsort(variant_codes(P), kind="stable")


RATES_BITS = ((1 << B_RIGID) | (1 << B_AMP) | (1 << B_AMP_BW) | (3 << B_FRIC_L) | (1 << B_TRANS)
              | (1 << B_THERMAL))
"""The bits of a variant code its generated state equations read besides static friction at the
motor (``sim.layout.source``: the states it integrates, the holds it can have, the flags the
rates take; ``tests/unit/test_rates_key.py`` checks the flags against every code)."""


def rates_key(code: int) -> int:
    """The part of a variant code its integration depends on at compile time: its generated
    state equations with the flags they read (``sim.layout.source``) and whether it locates
    static friction's switches (``sim.integrate.advance_for``). The variants with one key share
    one compiled integrator (RK4 and the switch search); the flags it does not fix (the
    controller, the extras, the motor's LuGre law) are read from the caller's ``Flags`` and
    folded once it is inlined into the variant's kernel. The paper's EMA's variants (motor
    friction none or LuGre, with or without extras) all have key 0."""
    code = int(code)
    key = code & RATES_BITS
    if code & 3 == FRIC_STATIC:
        key |= FRIC_STATIC
    return key


def one_lane_only(code: int) -> bool:
    """Whether a variant runs one lane at a time whatever the batch's width: a sampled
    controller, a quantiser or a compensator (the extras), static friction (stick-slip), a
    controller other than the paper's: their branches keep the compiler from vectorising."""
    code = int(code)
    fric_l = (code >> B_FRIC_L) & 3
    return bool((code >> B_EXTRAS) & 1 or code & 3 == FRIC_STATIC or fric_l == LFRIC_STATIC
                or (code >> B_CTRL) & 3)


def variant_keys(codes: np.ndarray, lanes: int) -> np.ndarray:
    """The entry-point variant each code of :func:`variant_codes` runs as in lanes (16) or one
    lane (1): one lane has one LuGre variant (any exponent: ``pow_nb``'s own branch skips the
    log and exp for an exponent of 1) for both LuGre codes, so the keys keep the codes' order
    (rows sorted by code stay grouped by key)."""
    codes = np.asarray(codes, dtype=np.int64)
    if lanes == 1:
        return np.where(codes & 3 == FRIC_LUGRE1, codes + 1, codes)
    return codes.copy()


def variant_args(code: int, lanes: int) -> int:
    """The variant argument of an entry point for ``code`` in lanes (16) or one lane (1)."""
    return int(variant_keys(np.array([code]), lanes)[0])


VARIANTS = {1: (0, 2, 4, 6), LANES: (0, 1, 2)}
"""The paper's EMA's variants each lane width runs, compiled ahead (``ema compile``): the extras
(codes 4-6) run one lane at a time (:func:`one_lane_only`), so lanes never need them; the
variants of other actuator descriptions compile the first time a run needs them."""

"""Static friction laws with stiction (Coulomb, Stribeck, viscous, per direction) (numba).

A friction site (the motor shaft, the load, or the one body of a rigid axis) in *slip* at
speed ``v`` in direction ``d = sign(v)`` feels::

    F = d*g_d(|v|) + Fv_d*v                       (opposes the motion)
    g_d(s) = Fc_d + (Fs_d - Fc_d)*exp(-(s/vs)**delta)        (Stribeck; vs = 0: g = Fc_d)

with the direction's own Coulomb level ``Fc_d``, breakaway (static) level ``Fs_d`` and viscous
coefficient ``Fv_d`` (``d = +``: moving in +x, ``d = -``: in -x; a symmetric law has equal
values). At rest the site *sticks*: its speed stays exactly 0 and the friction holds whatever
the other forces ``F_o`` on the body ask, as long as ``-Fs_- <= F_o <= Fs_+``; beyond, the body
breaks away in the direction of ``F_o``. A slipping body whose speed reaches 0 sticks when the
other forces are inside that band and slips on the other way otherwise (Karnopp's switch
model, with the switching instants located exactly by the simulator: ``sim.kernel``).

A constant offset force (gravity on an inclined axis, a bias, EMPS's ``OF``) is not friction:
it is ``load.offset`` (``model.plant``), a force opposing +x whatever the motion.
"""

from __future__ import annotations

from ema_cli._numba import njit
from ema_cli.model.vmath import exp_nb, pow_nb


@njit(cache=True, forceinline=True, error_model="numpy")
def stribeck_level_nb(s, fc, fs, vs, delta):
    """``g(s) = Fc + (Fs - Fc)*exp(-(s/vs)**delta)`` at speed ``s >= 0``; ``Fc`` when
    ``vs = 0`` (Coulomb) or ``Fs == Fc``."""
    if vs > 0.0 and fs != fc:
        return fc + (fs - fc) * exp_nb(-pow_nb(s / vs, delta))
    return fc


@njit(cache=True, forceinline=True, error_model="numpy")
def slip_friction_nb(v, d, fc_p, fc_n, fs_p, fs_n, vs, delta, fv_p, fv_n):
    """Friction force in slip [N or N*m] at speed ``v`` in direction ``d`` (+1 or -1; the
    direction of the slip, which a speed of exactly 0 at the start of a slip does not tell):
    ``d*g_d(|v|) + Fv_d*v``."""
    if d > 0.0:
        return stribeck_level_nb(abs(v), fc_p, fs_p, vs, delta) + fv_p * v
    return -stribeck_level_nb(abs(v), fc_n, fs_n, vs, delta) + fv_n * v


@njit(cache=True, forceinline=True, error_model="numpy")
def holds_nb(f_other, fs_p, fs_n):
    """Whether a site at rest stays stuck under the other forces ``f_other``:
    ``-Fs_- <= F_o <= Fs_+``."""
    return -fs_n <= f_other <= fs_p


@njit(cache=True, forceinline=True, error_model="numpy")
def steady_static_friction_nb(v, fc_p, fc_n, fs_p, fs_n, vs, delta, fv_p, fv_n):
    """The law's steady friction at constant speed ``v`` (0 at rest): the friction map a
    constant-speed sweep measures."""
    if v > 0.0:
        return slip_friction_nb(v, 1.0, fc_p, fc_n, fs_p, fs_n, vs, delta, fv_p, fv_n)
    if v < 0.0:
        return slip_friction_nb(v, -1.0, fc_p, fc_n, fs_p, fs_n, vs, delta, fv_p, fv_n)
    return 0.0

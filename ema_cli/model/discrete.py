"""The described discrete cascade: sampled position and velocity loops of a real drive (numba).

At every sample ``k`` (period ``Ts``), from the measured position ``q`` (the position sensor,
after its dead zone and quantiser, in the axis's units) and the reference ``r``::

    qf[k]  = sum_i b_i q[k-i]                     FIR on the position (taps dc_fir*; 1: none)
    v_e[k] = (qf[k] - qf[k-n]) / (n Ts)            velocity from the encoder, n = dc_ndiff
         or  the speed sensor / m                  (dc_vsrc = sensor)
    v[k]   = a v[k-1] + (1 - a) v_e[k],  a = exp(-2 pi fc Ts)   (fc = dc_vfc; 0: v = v_e)
    e[k]   = r[k] - q[k]
    v*[k]  = SAT(Kp e[k] + Ki xp[k], vmax)         position P or PI
    u'[k]  = Kv (v*[k] - v[k]) + Kvi xv[k]         velocity P or PI
    u[k]   = SAT(u'[k], umax)
    xp[k+1] = xp[k] + Ts e[k],  xv[k+1] = xv[k] + Ts (v*[k] - v[k])   (forward Euler; each
             integral stops while its loop's output is limited and the error pushes further)
    applied[k] = u[k - d]                          computation delay of d = dc_delay samples

The applied command is held until the next sample (zero-order hold). Samples before the first
(``q[k-i]``, ``u[k-d]`` with a negative index) are the initial position and 0. The EMPS
benchmark's controller is ``Kp = kp``, ``Kv = kv``, taps ``[0.5, 0.5]``, ``n = 1`` (a central
difference over two samples), ``umax = 10 V``, ``d = 1`` in its Simulink model (and ``d = 0`` in
the measured log: the command logged at sample k is the one computed from sample k).

The cascade's memory is one buffer per lane, laid out here (``BUFFER``): the position history,
the delay line, the velocity filter and the two integrals. ``sim.layout`` reserves the rows.
"""

from __future__ import annotations

import math

from ema_cli._numba import njit
from ema_cli.model.elements import saturate_nb
from ema_cli.model.params import MAX_DELAY, MAX_DIFF, MAX_FIR

HIST = MAX_FIR - 1 + MAX_DIFF + 1  # position samples kept: q[k] .. q[k-HIST+1] [samples]
B_HIST = 0  # buffer offsets: position history, newest first
B_DELAY = B_HIST + HIST  # delay line: commands computed 1 .. MAX_DELAY samples ago
B_VF = B_DELAY + MAX_DELAY  # the filtered velocity v[k-1]
B_XP = B_VF + 1  # position integral xp
B_XV = B_XP + 1  # velocity integral xv
B_PRIMED = B_XV + 1  # 1 once the history holds real samples (the first sample fills it)
BUFFER = B_PRIMED + 1  # rows of one lane's buffer


@njit(cache=True, forceinline=True, error_model="numpy", entry=True)
def filter_coefficient_nb(fc, ts):
    """``a = exp(-2 pi fc Ts)`` of the velocity low-pass (0 for ``fc = 0``: no filter)."""
    return math.exp(-2.0 * math.pi * fc * ts) if fc > 0.0 else 0.0


@njit(cache=True, error_model="numpy", entry=True)
def discrete_sample_nb(buf, q, v_sensor, r, ts, kp, ki, vmax, kv, kvi, umax, vsrc, ndiff,
                       taps, a_vf, delay):
    """One sample of the cascade (module docstring): update the buffer ``buf[BUFFER]`` in place
    -> the command applied from this sample on. ``q`` measured position, ``v_sensor`` the speed
    sensor's load-side velocity, ``r`` the reference (axis units), ``taps`` the FIR's
    ``MAX_FIR`` taps, ``ndiff`` and ``delay`` whole numbers (floats), ``vsrc`` 1 for the sensor."""
    n = int(ndiff)
    if buf[B_PRIMED] == 0.0:  # before the first sample the axis rested at q
        for k in range(HIST):
            buf[B_HIST + k] = q
        buf[B_PRIMED] = 1.0
    for k in range(HIST - 1, 0, -1):
        buf[B_HIST + k] = buf[B_HIST + k - 1]
    buf[B_HIST] = q
    if vsrc == 1.0:
        v_raw = v_sensor
    else:
        qf0 = 0.0
        qfn = 0.0
        for i in range(MAX_FIR):
            qf0 += taps[i] * buf[B_HIST + i]
            qfn += taps[i] * buf[B_HIST + i + n]
        v_raw = (qf0 - qfn) / (n * ts)
    v = a_vf * buf[B_VF] + (1.0 - a_vf) * v_raw if a_vf > 0.0 else v_raw
    buf[B_VF] = v
    e = r - q
    vs_unsat = kp * e + ki * buf[B_XP]
    v_star = saturate_nb(vs_unsat, vmax)
    ev = v_star - v
    u_unsat = kv * ev + kvi * buf[B_XV]
    u = saturate_nb(u_unsat, umax)
    if ki != 0.0 and not (abs(vs_unsat) > vmax and e * vs_unsat > 0.0):
        buf[B_XP] += ts * e
    if kvi != 0.0 and not (abs(u_unsat) > umax and ev * u_unsat > 0.0):
        buf[B_XV] += ts * ev
    d = int(delay)
    if d == 0:
        return u
    applied = buf[B_DELAY + d - 1]
    for k in range(d - 1, 0, -1):
        buf[B_DELAY + k] = buf[B_DELAY + k - 1]
    buf[B_DELAY] = u
    return applied

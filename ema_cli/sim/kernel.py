"""The batched fixed-step kernel (numba): RK4 across SIMD lanes, exact LuGre bristle update.

The model's equations live in ``ema_cli.model`` (plant, controller, transmission, LuGre,
elements); this module only integrates them, records the signals and accumulates the metrics.

Layout
------
A batch ``P[n_cases, N_PARAMS]`` (columns: ``model.params.PARAMS``) is cut into chunks of up to
``lanes`` configurations. A chunk is advanced *together*: its parameters, states and metric
accumulators are held as ``[quantity, lane]`` arrays (structure of arrays, the lane axis
innermost) and every time step is one loop over the lanes whose body is branch-free (selects,
``min``/``max``, the ``model.vmath`` functions), so the compiler vectorises it (AVX-512: 8 lanes
per instruction). Chunks are spread over the cores with ``prange``. The time loop of a chunk
is compiled once per kernel variant (:func:`variant_codes`: with or without friction, with the
default Stribeck exponent 1 or any other, with or without the digital controller, quantisers
and compensators; the locked motor is a select in all), each a function of its own that
carries only what its lanes need. The variant is a compile-time argument of the entry points,
so a variant is compiled (or loaded from the cache) only when a batch first needs it; the
runner sorts a batch's rows by variant (:func:`variant_order`, :func:`variant_keys`) and calls
each variant's entry point for its rows.
One configuration is a chunk of one lane: the same code, so a batch equals its single runs bit
for bit, and the serial and the parallel entry points give identical results (no fast-math, no
reassociation).

Numerics
--------
* RK4 for ``theta_m, w_m, i, theta_L, w_L, xI`` with the reference and the load-torque profile
  sampled at the stage times (half steps).
* The LuGre bristle state is advanced with the exact solution for the motor speed frozen over
  the step and its torque (exact step averages) held over the RK4 stages; the viscous part
  ``sigma2*w_m`` is evaluated at every stage (``model.lugre``).
* Current limit: ``di/dt = 0`` while ``|i| >= sat3`` and pushing outward; ``i`` is clamped to
  ``+-sat3`` after each step. Clamping anti-windup on the speed PI while SAT2 is active.
* Digital controller (``Ts > 0``, a whole number ``Ts/dt`` of steps): the cascade is evaluated
  at the sample instants from the state there, the voltage demand is held until the next one and
  the integral advances by forward Euler; between samples the integral has no rate.
* Locked motor: ``theta_m, w_m, i, xI`` keep their initial 0 (controller and armature off).
* A non-finite state or one past the runaway bounds marks the lane diverged: its metrics are NaN
  except ``diverged = 1`` and ``t_end``; its later samples are NaN. Other lanes are unaffected.

Time chunks
-----------
An entry point advances steps ``k0 <= k < k1`` of a run of ``n_steps`` steps (``k`` runs to
``n_steps`` inclusive: the last step only records and accumulates). Everything that must persist
between calls lives in the caller's state array ``S`` (one work array per chunk of lanes):
the first call (``k0 == 0``) fills it from ``P``, later calls resume from it, and only the call
that reaches the end (``k1 == n_steps + 1``) finishes the metrics. The inputs are given for the
steps of the call only (``ref_pos[:, 2*(k-k0)]`` is the reference at ``t_k``). Every step index
the numerics use (the trapezoid end weights, the steady-state and oscillation windows, the
recording instants, the divergence checks) is absolute, so a run cut into any chunks is bit for
bit the run done in one call. A run done in one call may pass an empty ``S``.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ema_cli._numba import literally, njit, prange
from ema_cli.model.controller import (
    cascade_nb,
    deadzone_inverse_nb,
    friction_ff_nb,
    integral_rate_nb,
    integral_update_nb,
    notch_gain_nb,
    notch_update_nb,
    sensors_nb,
)
from ema_cli.model.elements import dead_zone_nb, saturate_nb
from ema_cli.model.lugre import bristle_step_nb
from ema_cli.model.params import INDEX, INITIAL_STATE, N_PARAMS
from ema_cli.model.plant import (
    N_STATES,
    STATE_INDEX,
    armature_rate_nb,
    load_accel_nb,
    load_torque_nb,
    motor_accel_nb,
)
from ema_cli.model.transmission import shaft_torque_nb
from ema_cli.sim.tables import MET, N_METRICS, N_SIGNALS, SIG

# parameter rows (model.params.PARAMS order) of the work array W below
_R, _L, _KT, _KE = INDEX["R"], INDEX["L"], INDEX["Kt"], INDEX["Ke"]
_JM, _BM, _M, _JL, _BL = INDEX["Jm"], INDEX["bm"], INDEX["m"], INDEX["JL"], INDEX["bL"]
_KL, _C, _ALPHA, _DAMP = INDEX["kL"], INDEX["c"], INDEX["alpha"], INDEX["damping"]
_TAU, _HC, _PEN = INDEX["contact_tau"], INDEX["contact_hc"], INDEX["contact_pen"]
_KPP, _KPS, _KIS = INDEX["Kpp"], INDEX["Kps"], INDEX["Kis"]
_SAT1, _SAT2, _SAT3 = INDEX["sat1"], INDEX["sat2"], INDEX["sat3"]
_D1, _D3, _D4 = INDEX["d1"], INDEX["d3"], INDEX["d4"]
_FRIC, _FC, _FS, _VS, _DELTA = (INDEX[k] for k in ("friction", "Fc", "Fs", "vs", "delta"))
_SIG0, _SIG1, _SIG2 = INDEX["sigma0"], INDEX["sigma1"], INDEX["sigma2"]
_TLOAD, _KH, _LOCKED = INDEX["T_load"], INDEX["k_h"], INDEX["locked"]
_TS, _QPOS, _QSPEED = INDEX["Ts"], INDEX["q_pos"], INDEX["q_speed"]
_FB = INDEX["fb_motor"]
_DZI, _DZIB = INDEX["dzi_v"], INDEX["dzi_band"]
_FFC, _FFS, _FFV, _FFS2, _FFB = (INDEX[k] for k in ("ff_fc", "ff_fs", "ff_vs", "ff_sigma2",
                                                    "ff_band"))
_NHZ, _NDEPTH, _NZETA = INDEX["notch_hz"], INDEX["notch_depth"], INDEX["notch_zeta"]
_FFSIG0, _FFSIG1 = INDEX["ff_sigma0"], INDEX["ff_sigma1"]
_XINIT = INDEX[INITIAL_STATE[0]]  # first of the N_STATES initial-state columns, STATES order

# signal columns (W's recording rows, sig) and metric columns (met)
_S_BRISTLE_Z = SIG["bristle_z"]
_S_CURRENT = SIG["current"]
_S_DOMEGA = SIG["domega"]
_S_DTHETA = SIG["dtheta"]
_S_ERR_POS = SIG["err_pos"]
_S_ERR_VEL = SIG["err_vel"]
_S_OMEGA_LOAD = SIG["omega_load"]
_S_OMEGA_MOTOR = SIG["omega_motor"]
_S_OMEGA_REF = SIG["omega_ref"]
_S_THETA_LOAD = SIG["theta_load"]
_S_THETA_MOTOR = SIG["theta_motor"]
_S_THETA_REF = SIG["theta_ref"]
_S_TORQUE_FRICTION = SIG["torque_friction"]
_S_TORQUE_LOAD = SIG["torque_load"]
_S_TORQUE_SHAFT = SIG["torque_shaft"]
_S_VOLTAGE_AMP = SIG["voltage_amp"]
_S_VOLTAGE_CMD = SIG["voltage_cmd"]
_M_DIVERGED = MET["diverged"]
_M_IAE_POS = MET["iae_pos"]
_M_IAE_VEL = MET["iae_vel"]
_M_ISE_POS = MET["ise_pos"]
_M_ISE_VEL = MET["ise_vel"]
_M_ITAE_POS = MET["itae_pos"]
_M_ITAE_VEL = MET["itae_vel"]
_M_MAX_POS = MET["max_pos"]
_M_MAX_VEL = MET["max_vel"]
_M_OVERSHOOT = MET["overshoot"]
_M_P2P_POS = MET["p2p_pos"]
_M_P2P_VEL = MET["p2p_vel"]
_M_PEAK_CURRENT = MET["peak_current"]
_M_PEAK_LOAD_RATE = MET["peak_load_rate"]
_M_PEAK_TORQUE = MET["peak_torque"]
_M_PEAK_VOLTAGE = MET["peak_voltage"]
_M_RISE_TIME = MET["rise_time"]
_M_RMS_POS = MET["rms_pos"]
_M_RMS_VEL = MET["rms_vel"]
_M_SETTLING_TIME = MET["settling_time"]
_M_SS_ERR_POS = MET["ss_err_pos"]
_M_T50 = MET["t50"]
_M_STEP_PEAK = MET["step_peak"]
_M_T_END = MET["t_end"]

# Rows of a chunk's work array W[_N_ROWS, lanes] (one array, so that the compiler sees constant
# distances between all the rows a lane step reads and writes, and vectorises without run-time
# alias checks): the parameters (model.params order), then derived constants, controller and
# status values, states, metric accumulators, this step's inputs and the recorded values.
_P0 = 0
_D0 = _P0 + N_PARAMS
# 1/m, 1/L, 1/Jm, 1/JL, contact form?, steps per controller sample, sample countdown, held
# voltage, running?, step it diverged at, is the input a step?, step size, step time, 1/q_pos,
# 1/q_speed, notch: w and output gain, notch states x1, x2, friction observer's bristle state,
# 1/contact_tau (inf: none), contact_hc/contact_pen
(_D_INVM, _D_INVL, _D_INVJM, _D_INVJL, _D_CONTACT, _D_NS, _D_CNT, _D_UH, _D_ALIVE, _D_KEND,
 _D_ISSTEP, _D_STEP, _D_TSTEP, _D_INVQP, _D_INVQS, _D_NW, _D_NC, _D_XN1,
 _D_XN2, _D_ZH, _D_INVTAU, _D_HCK) = range(_D0, _D0 + 22)
_X0 = _D0 + 22
_X_THM, _X_WM, _X_I = (_X0 + STATE_INDEX[k] for k in ("theta_m", "w_m", "i"))
_X_THL, _X_WL = _X0 + STATE_INDEX["theta_L"], _X0 + STATE_INDEX["w_L"]
_X_Z, _X_XI = _X0 + STATE_INDEX["z"], _X0 + STATE_INDEX["xI"]
_A0 = _X0 + N_STATES
(_A_IAE, _A_ISE, _A_ITAE, _A_IAEV, _A_ISEV, _A_ITAEV, _A_EMAX, _A_EVMAX, _A_SS, _A_EMIN_O,
 _A_EMAX_O, _A_EVMIN_O, _A_EVMAX_O, _A_SMAX, _A_T10, _A_T50, _A_T90, _A_LAST, _A_PKI, _A_PKU,
 _A_PKWL, _A_PKT) = range(_A0, _A0 + 22)
_N_ACC = 22
_U0 = _A0 + _N_ACC  # inputs: reference at t, t+dt/2, t+dt; its velocity; load profile likewise
_U_R0, _U_R1, _U_R2, _U_RV, _U_L0, _U_L1, _U_L2 = range(_U0, _U0 + 7)
_REC0 = _U0 + 7  # recorded signals, in tables.SIGNALS order
_N_ROWS = _REC0 + N_SIGNALS
N_ROWS = _N_ROWS  # rows of a work array (the state array S of the entry points has this many)
ALIVE_ROW = _D_ALIVE  # the row of S that is 0 once a lane has diverged

LANE_PARAMS: tuple[tuple[str, int, bool], ...] = (
    ("m", _M, False),
    ("inv_m", _D_INVM, False),
    ("inv_l", _D_INVL, False),
    ("inv_jm", _D_INVJM, False),
    ("inv_jl", _D_INVJL, False),
    ("r_a", _R, False),
    ("kt", _KT, False),
    ("ke", _KE, False),
    ("bm", _BM, False),
    ("bl", _BL, False),
    ("kl", _KL, False),
    ("alpha", _ALPHA, False),
    ("c", _C, False),
    ("contact", _D_CONTACT, True),
    ("kpp", _KPP, False),
    ("kps", _KPS, False),
    ("kis", _KIS, False),
    ("sat1", _SAT1, False),
    ("sat2", _SAT2, False),
    ("sat3", _SAT3, False),
    ("d1", _D1, False),
    ("d3", _D3, False),
    ("d4", _D4, False),
    ("q_pos", _QPOS, False),
    ("q_speed", _QSPEED, False),
    ("t_const", _TLOAD, False),
    ("k_h", _KH, False),
    ("fr", _FRIC, True),
    ("fc", _FC, False),
    ("fs", _FS, False),
    ("vs", _VS, False),
    ("delta", _DELTA, False),
    ("sig0", _SIG0, False),
    ("sig1", _SIG1, False),
    ("sig2", _SIG2, False),
    ("ns", _D_NS, False),
    ("ts", _TS, False),
    ("locked", _LOCKED, True),
    ("is_step", _D_ISSTEP, True),
    ("step", _D_STEP, False),
    ("t_step", _D_TSTEP, False),
    ("inv_qp", _D_INVQP, False),
    ("inv_qs", _D_INVQS, False),
    ("fb", _FB, False),
    ("dzi", _DZI, False),
    ("dzib", _DZIB, False),
    ("ffc", _FFC, False),
    ("ffs", _FFS, False),
    ("ffv", _FFV, False),
    ("ffs2", _FFS2, False),
    ("ffb", _FFB, False),
    ("nw", _D_NW, False),
    ("nc", _D_NC, False),
    ("nz", _NZETA, False),
    ("ffsig0", _FFSIG0, False),
    ("ffsig1", _FFSIG1, False),
    ("inv_tau", _D_INVTAU, False),
    ("hc", _HC, False),
    ("hck", _D_HCK, False),
)
"""The lane parameter bundle :func:`_lane_params` builds, one entry per field: (name, row of
the work array W, read as a flag: ``row != 0``). Names as in ``model.params`` lower-cased where
they are parameters (``kl`` is ``kL``, ``sig0`` is ``sigma0``, ``t_const`` is ``T_load``), the
derived constants as their rows ``_D_*`` say (``inv_m`` is 1/m, ``ns`` the steps per controller
sample)."""
LaneParams = namedtuple("LaneParams", [f[0] for f in LANE_PARAMS])  # type: ignore[misc]
"""The parameters of one lane, by name (numba passes it as a struct: no cost over a tuple)."""

W_RUNAWAY = 1.0e5  # |w_m| above this is a runaway [rad/s] (~1e6 rpm)
THETA_RUNAWAY = 1.0e4  # |theta_L| above this is a runaway [rad]
I_RUNAWAY = 1.0e5  # |i| above this is a runaway [A]
SS_FRACTION = 0.9  # steady-state error: mean over t >= 0.9*T
OSC_FRACTION = 0.8  # residual oscillation: peak-to-peak over t >= 0.8*T
SETTLE_BAND = 0.02  # settling band, fraction of the step
LANES = 16  # configurations advanced together in a chunk (see make bench) [lanes]
ALIVE_CHECK = 1024  # steps between checks whether a chunk has any running lane left [steps]
_INF = np.inf
_NAN = np.nan


@njit(cache=True, forceinline=True, error_model="numpy")
def _rates(th_m, w_m, i, th_l, w_l, x_i, r, t_prof, prm, tf_b, visc, uh, disc, locked, extras,
           xn2, tfh, hw):
    """Time derivatives of (theta_m, w_m, i, theta_L, w_L, xI) for one lane (bristle torque
    ``tf_b``, held voltage ``uh``, notch state ``xn2`` and the friction observer's held bristle
    torque ``tfh`` given; ``hw`` = dt/2, the jump contact's regularisation, see
    ``model.transmission.shaft_torque_nb``). ``prm`` is the lane's :class:`LaneParams`."""
    q_pos = prm.q_pos if extras else 0.0  # no quantisers (a constant at each call site)
    q_speed = prm.q_speed if extras else 0.0
    th_meas, w_meas = sensors_nb(th_l, w_m, prm.d4, prm.d3, q_pos, q_speed, prm.inv_qp,
                                 prm.inv_qs, th_m * prm.inv_m, prm.fb)
    e_w, u_unsat, u_dem = cascade_nb(r, th_meas, w_meas, x_i, prm.m, prm.kpp, prm.kps, prm.kis,
                                     prm.sat1, prm.sat2)
    if extras:  # friction compensation, then the notch (held state)
        t_ff = (tfh + prm.ffs2 * w_meas if prm.ffsig0 > 0.0
                else friction_ff_nb(e_w + w_meas, w_meas, prm.ffc, prm.ffs, prm.ffv, prm.delta,
                                    prm.ffs2, prm.ffb))
        u_unsat = u_unsat + prm.r_a / prm.kt * t_ff + prm.nc * xn2
        u_dem = saturate_nb(u_unsat, prm.sat2)
    u = uh if disc else u_dem
    if extras:
        u = deadzone_inverse_nb(u, prm.dzi, prm.dzib)
    u_amp = 0.0 if locked else dead_zone_nb(u, prm.d1)
    t_shaft = shaft_torque_nb(prm.kl, prm.alpha, prm.c, prm.contact, prm.inv_tau, prm.hc,
                              prm.hck, th_m * prm.inv_m - th_l, w_m * prm.inv_m - w_l, hw)
    di = armature_rate_nb(i, w_m, u_amp, prm.r_a, prm.inv_l, prm.ke, prm.sat3)
    dxi = 0.0 if disc else integral_rate_nb(e_w, u_unsat, prm.sat2)
    dw_m = motor_accel_nb(i, w_m, t_shaft, tf_b + visc * w_m, prm.kt, prm.bm, prm.inv_m,
                          prm.inv_jm)
    dw_l = load_accel_nb(w_l, t_shaft, load_torque_nb(th_l, prm.t_const, t_prof, prm.k_h),
                         prm.bl, prm.inv_jl)
    # locked motor: the motor side keeps its state (selects, so every variant vectorises)
    return ((0.0 if locked else w_m), (0.0 if locked else dw_m), (0.0 if locked else di), w_l,
            dw_l, (0.0 if locked else dxi))


@njit(cache=True, forceinline=True, error_model="numpy")
def _lane_params(W, j):
    """The parameters of lane ``j`` as a :class:`LaneParams` (fields in :data:`LANE_PARAMS`
    order: ``tests/unit/test_kernel_bundles.py`` checks each field reads its row)."""
    return LaneParams(W[_M, j], W[_D_INVM, j], W[_D_INVL, j], W[_D_INVJM, j], W[_D_INVJL, j],
                      W[_R, j], W[_KT, j], W[_KE, j], W[_BM, j], W[_BL, j], W[_KL, j],
                      W[_ALPHA, j], W[_C, j], W[_D_CONTACT, j] != 0.0, W[_KPP, j], W[_KPS, j],
                      W[_KIS, j], W[_SAT1, j], W[_SAT2, j], W[_SAT3, j], W[_D1, j], W[_D3, j],
                      W[_D4, j], W[_QPOS, j], W[_QSPEED, j], W[_TLOAD, j], W[_KH, j],
                      W[_FRIC, j] != 0.0, W[_FC, j], W[_FS, j], W[_VS, j], W[_DELTA, j],
                      W[_SIG0, j], W[_SIG1, j], W[_SIG2, j], W[_D_NS, j], W[_TS, j],
                      W[_LOCKED, j] != 0.0, W[_D_ISSTEP, j] != 0.0, W[_D_STEP, j], W[_D_TSTEP, j],
                      W[_D_INVQP, j], W[_D_INVQS, j], W[_FB, j], W[_DZI, j], W[_DZIB, j],
                      W[_FFC, j], W[_FFS, j], W[_FFV, j], W[_FFS2, j], W[_FFB, j], W[_D_NW, j],
                      W[_D_NC, j], W[_NZETA, j], W[_FFSIG0, j], W[_FFSIG1, j], W[_D_INVTAU, j],
                      W[_HC, j], W[_D_HCK, j])


@njit(cache=True, forceinline=True, error_model="numpy")
def _load(W, j):
    """Lane ``j``'s states, accumulators, controller memory and inputs as tuples."""
    x = (W[_X_THM, j], W[_X_WM, j], W[_X_I, j], W[_X_THL, j], W[_X_WL, j], W[_X_Z, j],
         W[_X_XI, j])
    acc = (W[_A0, j], W[_A0 + 1, j], W[_A0 + 2, j], W[_A0 + 3, j], W[_A0 + 4, j],
           W[_A0 + 5, j], W[_A0 + 6, j], W[_A0 + 7, j], W[_A0 + 8, j], W[_A0 + 9, j],
           W[_A0 + 10, j], W[_A0 + 11, j], W[_A0 + 12, j], W[_A0 + 13, j], W[_A0 + 14, j],
           W[_A0 + 15, j], W[_A0 + 16, j], W[_A0 + 17, j], W[_A0 + 18, j], W[_A0 + 19, j],
           W[_A0 + 20, j], W[_A0 + 21, j])
    ctl = (W[_D_CNT, j], W[_D_UH, j], W[_D_ALIVE, j], W[_D_KEND, j], W[_D_XN1, j],
           W[_D_XN2, j], W[_D_ZH, j])
    return x, acc, ctl


@njit(cache=True, forceinline=True, error_model="numpy")
def _store(W, j, x, acc, ctl):
    """Write lane ``j``'s tuples back (the inverse of :func:`_load`)."""
    (W[_X_THM, j], W[_X_WM, j], W[_X_I, j], W[_X_THL, j], W[_X_WL, j], W[_X_Z, j],
     W[_X_XI, j]) = x
    (W[_A0, j], W[_A0 + 1, j], W[_A0 + 2, j], W[_A0 + 3, j], W[_A0 + 4, j], W[_A0 + 5, j],
     W[_A0 + 6, j], W[_A0 + 7, j], W[_A0 + 8, j], W[_A0 + 9, j], W[_A0 + 10, j], W[_A0 + 11, j],
     W[_A0 + 12, j], W[_A0 + 13, j], W[_A0 + 14, j], W[_A0 + 15, j], W[_A0 + 16, j],
     W[_A0 + 17, j], W[_A0 + 18, j], W[_A0 + 19, j], W[_A0 + 20, j], W[_A0 + 21, j]) = acc
    W[_D_CNT, j] = ctl[0]
    W[_D_UH, j] = ctl[1]
    W[_D_ALIVE, j] = ctl[2]
    W[_D_KEND, j] = ctl[3]
    W[_D_XN1, j] = ctl[4]
    W[_D_XN2, j] = ctl[5]
    W[_D_ZH, j] = ctl[6]


@njit(cache=True, forceinline=True, error_model="numpy")
def _record(W, j, x, inp, out, m):
    """Lane ``j``'s signals at the start of the step into W's recording rows (SI)."""
    th_m, w_m, i, th_l, w_l, z, _ = x
    u_out, u_amp, t_shaft, t_fric, t_load = out
    W[_REC0 + _S_THETA_REF, j] = inp[0]
    W[_REC0 + _S_THETA_LOAD, j] = th_l
    W[_REC0 + _S_THETA_MOTOR, j] = th_m / m
    W[_REC0 + _S_OMEGA_REF, j] = inp[3]
    W[_REC0 + _S_OMEGA_LOAD, j] = w_l
    W[_REC0 + _S_OMEGA_MOTOR, j] = w_m
    W[_REC0 + _S_CURRENT, j] = i
    W[_REC0 + _S_VOLTAGE_CMD, j] = u_out
    W[_REC0 + _S_VOLTAGE_AMP, j] = u_amp
    W[_REC0 + _S_TORQUE_SHAFT, j] = t_shaft
    W[_REC0 + _S_TORQUE_FRICTION, j] = t_fric
    W[_REC0 + _S_ERR_POS, j] = inp[0] - th_l
    W[_REC0 + _S_ERR_VEL, j] = inp[3] - w_l
    W[_REC0 + _S_DTHETA, j] = th_m / m - th_l
    W[_REC0 + _S_DOMEGA, j] = w_m / m - w_l
    W[_REC0 + _S_BRISTLE_Z, j] = z
    W[_REC0 + _S_TORQUE_LOAD, j] = t_load


@njit(cache=True, forceinline=True, error_model="numpy")
def _step(x, acc, ctl, inp, lp, k, dt, n_steps, in_ss, in_osc, fric, extras):
    """One time step of one lane: metrics at t_k, then RK4 to t_k+1 (a pure function).

    x = (theta_m, w_m, i, theta_L, w_L, z, xI); acc = the 22 metric accumulators (row order of
    ``_A_*``); ctl = (sample countdown, held voltage, alive, step where it diverged); inp =
    (reference at t, t+dt/2, t+dt, its velocity at t, load profile at t, t+dt/2, t+dt); lp =
    :func:`_lane_params` (a :class:`LaneParams`). ``fric`` (:func:`variant_codes`) 0 skips the
    LuGre update (no lane has friction), 1 takes the Stribeck exponent as 1; ``extras`` False
    skips the digital controller, the quantisers and the compensators (none is in use; the
    locked motor is a select in every variant); both are constants at each call site, so a
    variant carries only what it needs.
    Returns (x+, acc+, ctl+, (u_dem, u_amp, T, Tf, T_load) at t_k).
    """
    ns = lp.ns if extras else 0.0  # no digital controller (a constant at each call site)
    locked = lp.locked  # the locked motor: selects, in every variant
    q_pos = lp.q_pos if extras else 0.0
    q_speed = lp.q_speed if extras else 0.0
    delta = 1.0 if fric == 1 else lp.delta  # fric 1: every lane's exponent (pow_nb folds)
    th_m, w_m, i, th_l, w_l, z, x_i = x
    (iae, ise, itae, iaev, isev, itaev, emax, evmax, ss, emin_o, emax_o, evmin_o, evmax_o, smax,
     t10, t50, t90, last_out, pki, pku, pkwl, pkt) = acc
    cnt, uh, alive, kend, xn1, xn2, zh = ctl
    r0, r1, r2, rv, l0, l1, l2 = inp
    t = k * dt
    wgt = 0.5 * dt if (k == 0 or k == n_steps) else dt
    # --- LuGre bristle step (exact for frozen w_m), held over the RK4 stages
    if fric > 0:
        zb, tb = bristle_step_nb(z, w_m, dt, lp.fc, lp.fs, lp.vs, delta, lp.sig0, lp.sig1)
        z_new = zb if lp.fr else 0.0
        tf_b = tb if lp.fr else 0.0
        visc = lp.sig2 if lp.fr else 0.0
    else:
        z_new = 0.0
        tf_b = 0.0
        visc = 0.0
    # --- controller at t_k (digital: sample, hold, integrate)
    th_meas, w_meas = sensors_nb(th_l, w_m, lp.d4, lp.d3, q_pos, q_speed, lp.inv_qp, lp.inv_qs,
                                 th_m * lp.inv_m, lp.fb)
    e_w, u_unsat, u_dem = cascade_nb(r0, th_meas, w_meas, x_i, lp.m, lp.kpp, lp.kps, lp.kis,
                                     lp.sat1, lp.sat2)
    xn1_next, xn2_next = xn1, xn2
    zh_next = zh
    tfh = 0.0
    if extras:  # friction compensation (feed-forward or LuGre observer), then the notch
        r_a, kt = lp.r_a, lp.kt
        if lp.ffsig0 > 0.0:  # the observer's bristle state, advanced like the plant's (held)
            zh_next, tfh = bristle_step_nb(zh, w_meas, dt, lp.ffc, max(lp.ffs, lp.ffc), lp.ffv,
                                           delta, lp.ffsig0, lp.ffsig1)
            t_ff = tfh + lp.ffs2 * w_meas
        else:
            t_ff = friction_ff_nb(e_w + w_meas, w_meas, lp.ffc, lp.ffs, lp.ffv, delta, lp.ffs2,
                                  lp.ffb)
        u_pre = u_unsat + r_a / kt * t_ff
        u_unsat = u_pre + lp.nc * xn2
        u_dem = saturate_nb(u_unsat, lp.sat2)
        if lp.nw > 0.0:
            xn1_next, xn2_next = notch_update_nb(xn1, xn2, u_pre, lp.nw, lp.nz, dt)
    disc = ns > 0.0
    sample = disc and cnt == 0.0
    uh = u_dem if sample else uh
    x_i_next = integral_update_nb(x_i, e_w, u_unsat, lp.sat2, lp.ts) if sample else x_i
    cnt = ns - 1.0 if sample else cnt - 1.0
    u_out = 0.0 if locked else (uh if disc else u_dem)
    if extras:
        u_out = deadzone_inverse_nb(u_out, lp.dzi, lp.dzib)
    u_amp = dead_zone_nb(u_out, lp.d1)
    hw = 0.5 * dt  # the jump contact's regularisation band (model.transmission)
    t_shaft = shaft_torque_nb(lp.kl, lp.alpha, lp.c, lp.contact, lp.inv_tau, lp.hc, lp.hck,
                              th_m * lp.inv_m - th_l, w_m * lp.inv_m - w_l, hw)
    # --- metrics (trapezoid weights over the full-resolution samples)
    e = r0 - th_l
    ev = rv - w_l
    ae = abs(e)
    aev = abs(ev)
    iae += wgt * ae
    ise += wgt * e * e
    itae += wgt * t * ae
    iaev += wgt * aev
    isev += wgt * ev * ev
    itaev += wgt * t * aev
    emax = max(emax, ae)
    evmax = max(evmax, aev)
    if in_ss:
        ss += e
    if in_osc:
        emin_o = min(emin_o, e)
        emax_o = max(emax_o, e)
        evmin_o = min(evmin_o, ev)
        evmax_o = max(evmax_o, ev)
    pki = max(pki, abs(i))
    pku = max(pku, abs(u_out))
    pkwl = max(pkwl, abs(w_l))
    pkt = max(pkt, abs(t_shaft))
    act = lp.is_step and t >= lp.t_step
    s = th_l / lp.step
    smax = max(smax, s) if act else smax
    t10 = t if (act and t10 != t10 and s >= 0.1) else t10
    t50 = t if (act and t50 != t50 and s >= 0.5) else t50
    t90 = t if (act and t90 != t90 and s >= 0.9) else t90
    last_out = k if (act and abs(s - 1.0) > SETTLE_BAND) else last_out
    acc = (iae, ise, itae, iaev, isev, itaev, emax, evmax, ss, emin_o, emax_o, evmin_o, evmax_o,
           smax, t10, t50, t90, last_out, pki, pku, pkwl, pkt)
    out = (u_out, u_amp, t_shaft, tf_b + visc * w_m, load_torque_nb(th_l, lp.t_const, l0, lp.k_h))
    # --- RK4 step (reference and load profile at the stage times; bristle torque held)
    x_i = x_i_next
    h = dt
    a1, b1, c1, d1, e1, f1 = _rates(th_m, w_m, i, th_l, w_l, x_i, r0, l0, lp, tf_b, visc,
                                    uh, disc, locked, extras, xn2, tfh, hw)
    a2, b2, c2, d2, e2, f2 = _rates(th_m + 0.5 * h * a1, w_m + 0.5 * h * b1,
                                    i + 0.5 * h * c1, th_l + 0.5 * h * d1,
                                    w_l + 0.5 * h * e1, x_i + 0.5 * h * f1, r1, l1, lp,
                                    tf_b, visc, uh, disc, locked, extras, xn2, tfh, hw)
    a3, b3, c3, d3, e3, f3 = _rates(th_m + 0.5 * h * a2, w_m + 0.5 * h * b2,
                                    i + 0.5 * h * c2, th_l + 0.5 * h * d2,
                                    w_l + 0.5 * h * e2, x_i + 0.5 * h * f2, r1, l1, lp,
                                    tf_b, visc, uh, disc, locked, extras, xn2, tfh, hw)
    a4, b4, c4, d4, e4, f4 = _rates(th_m + h * a3, w_m + h * b3, i + h * c3, th_l + h * d3,
                                    w_l + h * e3, x_i + h * f3, r2, l2, lp, tf_b, visc,
                                    uh, disc, locked, extras, xn2, tfh, hw)
    h6 = h / 6.0
    th_m += h6 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    w_m += h6 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    i += h6 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
    th_l += h6 * (d1 + 2.0 * d2 + 2.0 * d3 + d4)
    w_l += h6 * (e1 + 2.0 * e2 + 2.0 * e3 + e4)
    x_i += h6 * (f1 + 2.0 * f2 + 2.0 * f3 + f4)
    i = min(max(i, -lp.sat3), lp.sat3)
    ok = (abs(w_m) < W_RUNAWAY and abs(th_l) < THETA_RUNAWAY and abs(i) < I_RUNAWAY
          and abs(th_m) < _INF and abs(w_l) < _INF and abs(x_i) < _INF and abs(z_new) < _INF)
    dies = alive != 0.0 and not ok and k < n_steps
    kend = k + 1.0 if dies else kend
    alive = 0.0 if dies else alive
    return (th_m, w_m, i, th_l, w_l, z_new, x_i), acc, (cnt, uh, alive, kend, xn1_next,
                                                        xn2_next, zh_next), out


@njit(cache=True, forceinline=True, error_model="numpy")
def _advance(W, k, dt, n_steps, in_ss, in_osc, record, fric_chunk, extras):
    """One time step of every lane of a chunk (the lane loop the compiler vectorises)."""
    for j in range(W.shape[1]):
        x, acc, ctl = _load(W, j)
        lp = _lane_params(W, j)
        inp = (W[_U_R0, j], W[_U_R1, j], W[_U_R2, j], W[_U_RV, j], W[_U_L0, j], W[_U_L1, j],
               W[_U_L2, j])
        xn, acc, ctl, out = _step(x, acc, ctl, inp, lp, k, dt, n_steps, in_ss, in_osc,
                                  fric_chunk, extras)
        if record:
            _record(W, j, x, inp, out, lp.m)
        _store(W, j, xn, acc, ctl)


@njit(cache=True, forceinline=True, error_model="numpy")
def _lane_needs(W, j):
    """What lane ``j`` of ``W`` (rows: model.params order first) needs of the kernel: (friction,
    Stribeck exponent 1, extras: the digital controller, a quantiser or a compensator; the
    locked motor runs in every variant). The one definition :func:`variant_codes` and
    :func:`variant_order` use."""
    extras = (W[_TS, j] > 0.0 or W[_QPOS, j] > 0.0 or W[_QSPEED, j] > 0.0
              or W[_DZI, j] > 0.0 or W[_FFC, j] > 0.0
              or W[_FFS2, j] > 0.0 or W[_NHZ, j] > 0.0 or W[_FFSIG0, j] > 0.0)
    return W[_FRIC, j] != 0.0, W[_DELTA, j] == 1.0, extras


@njit(cache=True, error_model="numpy")
def _variant_codes_nb(PT):
    """Per configuration (column of ``PT[N_PARAMS, n_cases]``), the variant it needs alone as
    one number, cheapest first: 3*extras + (0 no friction, 1 exponent 1, 2 any other)."""
    out = np.empty(PT.shape[1], dtype=np.int64)
    for j in range(PT.shape[1]):
        f, u, e = _lane_needs(PT, j)
        out[j] = 3 * e + (0 if not f else (1 if u else 2))
    return out


def variant_order(P: np.ndarray) -> np.ndarray:
    """The rows of ``P[n_cases, N_PARAMS]`` sorted (stably) by the kernel variant they need
    (:func:`variant_codes`, cheapest first), so that the rows of one variant are contiguous:
    the permutation ``order`` (run ``P[order]``)."""
    return np.argsort(_variant_codes_nb(P.T), kind="stable")


@njit(cache=True, forceinline=True, error_model="numpy")
def _init(W, n_real, step_info, qidx, dt, n_steps):
    """Fill the derived rows, accumulators and controller memory of every lane of ``W`` (the
    spare lanes beyond ``n_real`` copy lane 0's parameters)."""
    for j in range(W.shape[1]):
        jj = j if j < n_real else 0
        for c in range(N_PARAMS):
            W[_P0 + c, j] = W[_P0 + c, jj]
        W[_D_INVM, j] = 1.0 / W[_M, j]
        W[_D_INVL, j] = 1.0 / W[_L, j]
        W[_D_INVJM, j] = 1.0 / W[_JM, j]
        W[_D_INVJL, j] = 1.0 / W[_JL, j]
        W[_D_CONTACT, j] = 1.0 if W[_DAMP, j] == 0.0 else 0.0
        W[_D_INVTAU, j] = 1.0 / W[_TAU, j] if W[_TAU, j] > 0.0 else _INF
        W[_D_HCK, j] = W[_HC, j] / W[_PEN, j] if W[_HC, j] > 0.0 else 0.0
        W[_D_INVQP, j] = 1.0 / W[_QPOS, j] if W[_QPOS, j] > 0.0 else 0.0
        W[_D_INVQS, j] = 1.0 / W[_QSPEED, j] if W[_QSPEED, j] > 0.0 else 0.0
        if W[_NHZ, j] > 0.0:
            W[_D_NW, j], W[_D_NC, j] = notch_gain_nb(W[_NHZ, j], W[_NDEPTH, j], W[_NZETA, j])
        else:
            W[_D_NW, j], W[_D_NC, j] = 0.0, 0.0
        W[_D_XN1, j] = 0.0
        W[_D_XN2, j] = 0.0
        W[_D_ZH, j] = 0.0
        ts = W[_TS, j]
        W[_D_NS, j] = np.floor(ts / dt + 0.5) if ts > 0.0 else 0.0
        W[_D_ALIVE, j] = 1.0
        W[_D_KEND, j] = n_steps + 1.0  # the step it diverged at (never, unless set)
        for s in range(N_STATES):  # the initial state (model.params.INITIAL_STATE)
            W[_X0 + s, j] = W[_P0 + _XINIT + s, j]
        q = qidx[jj]
        W[_D_ISSTEP, j] = step_info[q, 0]
        W[_D_STEP, j] = step_info[q, 1]
        W[_D_TSTEP, j] = step_info[q, 2]
        W[_A_EMIN_O, j] = _INF
        W[_A_EMAX_O, j] = -_INF
        W[_A_EVMIN_O, j] = _INF
        W[_A_EVMAX_O, j] = -_INF
        W[_A_SMAX, j] = -_INF
        W[_A_T10, j] = _NAN
        W[_A_T50, j] = _NAN
        W[_A_T90, j] = _NAN
        W[_A_LAST, j] = -1.0


@njit(cache=True, error_model="numpy")
def _steps(W, n_real, ref_pos, ref_vel, load_half, qidx, dt, n_steps, k0, k1, dec, sig, rows,
           fric, extras):
    """Advance the lanes of ``W`` over steps ``k0..k1-1`` (see :func:`_run`) in the kernel
    variant (``fric``, ``extras``) of :func:`variant_codes`: compiled once per variant, each a
    function of its own, so the optimiser sees (and lays out) one variant at a time."""
    literally(fric)
    literally(extras)
    nl = W.shape[1]
    k_ss = int(np.ceil(SS_FRACTION * n_steps - 1e-9))
    k_osc = int(np.ceil(OSC_FRACTION * n_steps - 1e-9))
    has_load = load_half.shape[1] > 0
    countdown = (dec - k0 % dec) % dec if dec > 0 else 0  # steps until the next recorded sample
    n_alive = n_real
    if k0 > 0:  # resumed: nothing to do once every lane has diverged
        n_alive = 0
        for j in range(n_real):
            n_alive += W[_D_ALIVE, j] != 0.0
    for k in range(k0, k1 if n_alive > 0 else k0):
        # this step's inputs per lane (lanes may follow different references)
        cur = 2 * (k - k0)
        nxt = cur + 1 if k < n_steps else cur
        nxt2 = nxt + 1 if k < n_steps else nxt
        for j in range(nl):
            q = qidx[j if j < n_real else 0]
            W[_U_R0, j] = ref_pos[q, cur]
            W[_U_R1, j] = ref_pos[q, nxt]
            W[_U_R2, j] = ref_pos[q, nxt2]
            W[_U_RV, j] = ref_vel[q, k - k0]
            if has_load:
                W[_U_L0, j] = load_half[q, cur]
                W[_U_L1, j] = load_half[q, nxt]
                W[_U_L2, j] = load_half[q, nxt2]
        record = dec > 0 and countdown == 0
        _advance(W, k, dt, n_steps, k >= k_ss, k >= k_osc, record, fric, extras)
        if record:
            countdown = dec
            row = k // dec
            for j in range(n_real):
                dead = k >= W[_D_KEND, j]
                for s in range(N_SIGNALS):
                    sig[rows[j], row, s] = _NAN if dead else W[_REC0 + s, j]
        countdown -= 1
        if k % ALIVE_CHECK == ALIVE_CHECK - 1:
            n_alive = 0
            for j in range(n_real):
                n_alive += W[_D_ALIVE, j] != 0.0
            if n_alive == 0:
                break  # every lane diverged: the rest of the record stays NaN


@njit(cache=True, forceinline=True, error_model="numpy")
def _run(W, n_real, ref_pos, ref_vel, load_half, step_info, qidx, dt, n_steps, k0, k1, dec, sig,
         rows, met, fric, extras):
    """Advance the lanes of the work array ``W`` together over steps ``k0..k1-1`` in the kernel
    variant (``fric``, ``extras``) the caller chose for them (:func:`variant_codes`; the first
    ``n_real`` lanes are real, the rest padding copies of lane 0): initialise ``W`` when ``k0``
    is 0, record the signals of lane ``j`` into ``sig[rows[j]]`` and, when the run ends here,
    write its metrics into ``met[rows[j]]``."""
    if k0 == 0:
        _init(W, n_real, step_info, qidx, dt, n_steps)
    _steps(W, n_real, ref_pos, ref_vel, load_half, qidx, dt, n_steps, k0, k1, dec, sig, rows,
           fric, extras)
    if k1 > n_steps:
        _finish_metrics(W, n_real, dt, n_steps, int(np.ceil(SS_FRACTION * n_steps - 1e-9)), met,
                        rows)


@njit(cache=True, forceinline=True, error_model="numpy")
def _run_one(W, ref_pos, ref_vel, load_half, q, dt, n_steps, k0, k1, dec, sig, o, met, rows, fric,
             extras):
    """:func:`_run` for a single lane (row ``o`` of ``sig``) with its states held in registers
    (the same arithmetic, :func:`_step`, without the round trips through W)."""
    k_ss = int(np.ceil(SS_FRACTION * n_steps - 1e-9))
    k_osc = int(np.ceil(OSC_FRACTION * n_steps - 1e-9))
    has_load = load_half.shape[1] > 0
    x, acc, ctl = _load(W, 0)
    lp = _lane_params(W, 0)
    countdown = (dec - k0 % dec) % dec if dec > 0 else 0
    # a lane that diverged in an earlier call stays where it stopped (the rest stays NaN)
    for k in range(k0, k1 if ctl[2] != 0.0 else k0):
        cur = 2 * (k - k0)
        nxt = cur + 1 if k < n_steps else cur
        nxt2 = nxt + 1 if k < n_steps else nxt
        if has_load:
            inp = (ref_pos[q, cur], ref_pos[q, nxt], ref_pos[q, nxt2], ref_vel[q, k - k0],
                   load_half[q, cur], load_half[q, nxt], load_half[q, nxt2])
        else:
            inp = (ref_pos[q, cur], ref_pos[q, nxt], ref_pos[q, nxt2], ref_vel[q, k - k0],
                   0.0, 0.0, 0.0)
        xn, acc, ctl, out = _step(x, acc, ctl, inp, lp, k, dt, n_steps, k >= k_ss, k >= k_osc,
                                  fric, extras)
        if dec > 0 and countdown == 0:
            countdown = dec
            _record(W, 0, x, inp, out, lp.m)
            for s in range(N_SIGNALS):
                sig[o, k // dec, s] = W[_REC0 + s, 0]
        countdown -= 1
        x = xn
        if ctl[2] == 0.0:
            break  # diverged: the rest of the record stays NaN
    _store(W, 0, x, acc, ctl)
    if k1 > n_steps:
        _finish_metrics(W, 1, dt, n_steps, k_ss, met, rows)


@njit(cache=True, error_model="numpy")
def simulate_chunk_nb(P, a, b, S, g, ref_pos, ref_vel, load_half, step_info, ref_index, out_row,
                      dt, n_steps, k0, k1, dec, sig, met, fric, extras):
    """Advance rows ``a..b-1`` of ``P[n_cases, N_PARAMS]`` together in one chunk of
    :data:`LANES` lanes (``b - a <= LANES``; the spare lanes repeat row ``a`` and are dropped)
    over steps ``k0..k1-1``, their work array kept in ``S[g]`` between calls, in kernel variant
    (``fric``, ``extras``) (compile-time constants, :func:`variant_codes`).

    ref_pos[n_refs, 2*(k1-k0)+1, or 2*(k1-k0)-1 when k1 == n_steps+1] the reference at the half
    steps t = j*dt/2, j = 2*k0, 2*k0+1, ... (rad); ref_vel[n_refs, k1-k0] its velocity at the
    steps (rad/s); load_half[n_refs, like ref_pos, or 0 columns: no profile] (N*m);
    step_info[n_refs, 3] (is_step, final value rad, step time s); ref_index[n_cases] the
    reference of each row; out_row[n_cases] the row of sig and met each row of P writes.
    Writes, if ``dec`` > 0, the signals of the steps k0..k1-1 that are multiples of ``dec`` into
    sig[n_cases, n_out, N_SIGNALS] and, if k1 == n_steps + 1, the metrics into
    met[n_cases, N_METRICS].
    """
    W = np.zeros((_N_ROWS, LANES))
    if k0 == 0:
        for j in range(b - a):
            for c in range(N_PARAMS):
                W[_P0 + c, j] = P[a + j, c]
    else:
        for r in range(_N_ROWS):
            for j in range(LANES):
                W[r, j] = S[g, r, j]
    _run(W, b - a, ref_pos, ref_vel, load_half, step_info, ref_index[a:b], dt, n_steps, k0, k1,
         dec, sig, out_row[a:b], met, fric, extras)
    if k1 <= n_steps:
        for r in range(_N_ROWS):
            for j in range(LANES):
                S[g, r, j] = W[r, j]


@njit(cache=True, error_model="numpy")
def simulate_one_nb(P, a, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row, dt,
                    n_steps, k0, k1, dec, sig, met, fric, extras):
    """The same as :func:`simulate_chunk_nb` for the single row ``a`` (its work array kept in
    ``S[a]``): a chunk of one lane, its states kept in registers (the fastest path for a few
    configurations; identical results). One lane: pow_nb's own branch already skips the log
    and exp for an exponent of 1, so friction mode 2 serves both friction modes here."""
    W = np.empty((_N_ROWS, 1))
    if k0 == 0:
        for r in range(_N_ROWS):
            W[r, 0] = P[a, r - _P0] if _P0 <= r < _P0 + N_PARAMS else 0.0
        _init(W, 1, step_info, ref_index[a:a + 1], dt, n_steps)
    else:
        for r in range(_N_ROWS):
            W[r, 0] = S[a, r, 0]
    rows = out_row[a:a + 1]
    _run_one(W, ref_pos, ref_vel, load_half, ref_index[a], dt, n_steps, k0, k1, dec, sig,
             out_row[a], met, rows, fric, extras)
    if k1 <= n_steps:
        for r in range(_N_ROWS):
            S[a, r, 0] = W[r, 0]


@njit(cache=True, error_model="numpy")
def _finish_metrics(W, n_real, dt, n_steps, k_ss, met, rows):
    """Turn the accumulators of the first ``n_real`` lanes into met[rows[j], :] (SI)."""
    duration = n_steps * dt
    ss_n = n_steps + 1 - k_ss
    for j in range(n_real):
        out = met[rows[j]]
        if W[_D_ALIVE, j] == 0.0:
            for c in range(N_METRICS):
                out[c] = _NAN
            out[_M_DIVERGED] = 1.0
            out[_M_T_END] = W[_D_KEND, j] * dt
            continue
        out[_M_IAE_POS] = W[_A_IAE, j]
        out[_M_ISE_POS] = W[_A_ISE, j]
        out[_M_ITAE_POS] = W[_A_ITAE, j]
        out[_M_RMS_POS] = np.sqrt(W[_A_ISE, j] / duration)
        out[_M_MAX_POS] = W[_A_EMAX, j]
        out[_M_IAE_VEL] = W[_A_IAEV, j]
        out[_M_ISE_VEL] = W[_A_ISEV, j]
        out[_M_ITAE_VEL] = W[_A_ITAEV, j]
        out[_M_RMS_VEL] = np.sqrt(W[_A_ISEV, j] / duration)
        out[_M_MAX_VEL] = W[_A_EVMAX, j]
        out[_M_SS_ERR_POS] = W[_A_SS, j] / ss_n
        out[_M_P2P_POS] = W[_A_EMAX_O, j] - W[_A_EMIN_O, j]
        out[_M_P2P_VEL] = W[_A_EVMAX_O, j] - W[_A_EVMIN_O, j]
        out[_M_PEAK_CURRENT] = W[_A_PKI, j]
        out[_M_PEAK_VOLTAGE] = W[_A_PKU, j]
        out[_M_PEAK_LOAD_RATE] = W[_A_PKWL, j]
        out[_M_PEAK_TORQUE] = W[_A_PKT, j]
        out[_M_DIVERGED] = 0.0
        out[_M_T_END] = duration
        if W[_D_ISSTEP, j] != 0.0:
            t_step = W[_D_TSTEP, j]
            out[_M_OVERSHOOT] = max(0.0, W[_A_SMAX, j] - 1.0) * 100.0
            out[_M_RISE_TIME] = W[_A_T90, j] - W[_A_T10, j]
            out[_M_T50] = W[_A_T50, j] - t_step
            out[_M_STEP_PEAK] = W[_A_SMAX, j]
            last_out = W[_A_LAST, j]
            out[_M_SETTLING_TIME] = ((last_out + 1.0) * dt - t_step if last_out < n_steps
                                         else _NAN)
        else:
            out[_M_OVERSHOOT] = _NAN
            out[_M_RISE_TIME] = _NAN
            out[_M_T50] = _NAN
            out[_M_STEP_PEAK] = _NAN
            out[_M_SETTLING_TIME] = _NAN


@njit(cache=True, error_model="numpy")
def simulate_rows_nb(P, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row, dt,
                     n_steps, k0, k1, dec, sig, met, fric, extras):
    """Every row of P alone (:func:`simulate_one_nb`, state ``S[n_cases, N_ROWS, 1]``),
    serially; safe in any thread."""
    literally(fric)
    literally(extras)
    for a in range(P.shape[0]):
        simulate_one_nb(P, a, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row, dt,
                        n_steps, k0, k1, dec, sig, met, fric, extras)


@njit(cache=True, parallel=True, error_model="numpy")
def simulate_rows_parallel_nb(P, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row,
                              dt, n_steps, k0, k1, dec, sig, met, fric, extras):
    """:func:`simulate_rows_nb` with the rows spread over numba threads."""
    literally(fric)
    literally(extras)
    for a in prange(P.shape[0]):
        simulate_one_nb(P, a, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row, dt,
                        n_steps, k0, k1, dec, sig, met, fric, extras)


@njit(cache=True, error_model="numpy")
def simulate_lanes_nb(P, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row, dt,
                      n_steps, k0, k1, dec, sig, met, fric, extras):
    """Chunks of :data:`LANES` rows of P advanced together (:func:`simulate_chunk_nb`, state
    ``S[n_chunks, N_ROWS, LANES]``), serially; safe in any thread."""
    literally(fric)
    literally(extras)
    n = P.shape[0]
    for ch in range((n + LANES - 1) // LANES):
        a = ch * LANES
        simulate_chunk_nb(P, a, min(a + LANES, n), S, ch, ref_pos, ref_vel, load_half,
                          step_info, ref_index, out_row, dt, n_steps, k0, k1, dec, sig, met,
                          fric, extras)


@njit(cache=True, parallel=True, error_model="numpy")
def simulate_lanes_parallel_nb(P, S, ref_pos, ref_vel, load_half, step_info, ref_index, out_row,
                               dt, n_steps, k0, k1, dec, sig, met, fric, extras):
    """:func:`simulate_lanes_nb` with the chunks spread over numba threads."""
    literally(fric)
    literally(extras)
    n = P.shape[0]
    for ch in prange((n + LANES - 1) // LANES):
        a = ch * LANES
        simulate_chunk_nb(P, a, min(a + LANES, n), S, ch, ref_pos, ref_vel, load_half,
                          step_info, ref_index, out_row, dt, n_steps, k0, k1, dec, sig, met,
                          fric, extras)


KERNELS = {(False, False): simulate_rows_nb, (True, False): simulate_rows_parallel_nb,
           (False, True): simulate_lanes_nb, (True, True): simulate_lanes_parallel_nb}
"""Entry points by (parallel, in lanes); all take (P, S, ref_pos, ref_vel, load_half, step_info,
ref_index, out_row, dt, n_steps, k0, k1, dec, sig, met, fric, extras), see
:func:`simulate_chunk_nb`; ``fric`` and ``extras`` are compile-time constants: each variant is
compiled (or loaded from the cache) the first time it is asked for."""


def variant_codes(P: np.ndarray) -> np.ndarray:
    """Per row of ``P[n_cases, N_PARAMS]`` the kernel variant it needs alone, cheapest first:
    ``3*extras + fric`` (fric 0 no friction, 1 Stribeck exponent 1, 2 any other)."""
    return _variant_codes_nb(P.T)


def variant_keys(codes: np.ndarray, lanes: int) -> np.ndarray:
    """The entry-point variant ``3*extras + fric`` each code of :func:`variant_codes` runs in
    lanes (16) or one lane (1): one lane has one friction variant (2) for both modes, so the
    keys keep the codes' order (rows sorted by code stay grouped by key)."""
    fric, extras = codes % 3, codes >= 3
    if lanes == 1:
        fric = np.where(fric > 0, 2, 0)
    return fric + 3 * extras


def variant_args(code: int, lanes: int) -> tuple[int, bool]:
    """The (fric, extras) arguments of an entry point for variant ``code`` (:func:`variant_codes`)
    in lanes (16) or one lane (1) (see :func:`variant_keys`)."""
    key = int(variant_keys(np.array([code]), lanes)[0])
    return key % 3, key >= 3


VARIANTS = {1: ((0, False), (2, False), (0, True), (2, True)),
            LANES: tuple((f, e) for e in (False, True) for f in (0, 1, 2))}
"""The variants each lane width compiles: (fric, extras)."""

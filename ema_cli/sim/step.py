"""One time step of one lane, and the lane's set-up and metrics (numba, inlined into the kernel).

:func:`_step` takes a lane's state, accumulators, memory and inputs as named tuples
(``sim.layout``) and returns them one step on: the LuGre bristles (exact for frozen speed), the
controller at the step's instant (sampling, hold, the compensators, the discrete cascade's
command from :func:`_discrete_sample`), the metrics, then RK4 (``sim.integrate``) to the next
instant. :func:`_init` fills a work array's derived rows, memory, states and accumulators from
the parameters; :func:`_finish_metrics` turns the accumulators into the metrics.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ema_cli._numba import njit
from ema_cli.model.actuator import (
    CTRL_DISCRETE,
    CTRL_NONE,
    CTRL_PAPER,
    FRIC_LUGRE1,
    amplifier_input_nb,
    command_nb,
    controller_nb,
    flags_nb,
    plant_nb,
    shaft_nb,
)
from ema_cli.model.controller import integral_update_nb, notch_gain_nb, notch_update_nb
from ema_cli.model.discrete import BUFFER, discrete_sample_nb, filter_coefficient_nb
from ema_cli.model.lugre import bristle_step_nb
from ema_cli.model.params import INDEX, INITIAL_STATE, N_PARAMS
from ema_cli.sim import layout
from ema_cli.sim.integrate import advance_for, motor_follows, site_on
from ema_cli.sim.layout import (
    START,
    Out,
    R,
    Step,
    accumulate,
    init_acc,
    init_x,
    lane_params,
    load_acc,
    load_inp,
    load_mem,
    load_x,
    record,
    store_acc,
    store_mem,
    store_x,
)
from ema_cli.sim.tables import MET, N_METRICS

_P0 = START["param"]
_BUF0 = START["buffer"]
_MEM0 = START["memory"]
_STATE0 = START["state"]
_XINIT = _P0 + INDEX[INITIAL_STATE[0]]  # first of the initial-state columns, STATES order
MI = namedtuple("MetricColumns", list(MET))(*MET.values())  # type: ignore[misc]
"""The metric columns by attribute (a constant the compiled code reads)."""
W_RUNAWAY = 1.0e5  # |w_m| above this is a runaway [rad/s] (~1e6 rpm)
THETA_RUNAWAY = 1.0e4  # |theta_L| above this is a runaway [rad or m]
I_RUNAWAY = 1.0e5  # |i| above this is a runaway [A]
_INF = np.inf
_NAN = np.nan


@njit(cache=True, forceinline=True, error_model="numpy")
def step_nb(x, acc, mem, inp, lp, k, dt, n_steps, in_ss, in_osc, variant, dsc):
    """One time step of one lane: metrics at t_k, then RK4 to t_k+1 (a pure function).

    x, acc, mem, inp: the lane's state (:class:`sim.layout.X`), accumulators, memory and this
    step's inputs as named tuples; lp its parameters (``sim.layout.Lane``); ``variant`` the
    compile-time variant code (``model.actuator``): a variant carries only what its flags need;
    ``dsc`` the discrete cascade's new command when it samples at this step
    (:func:`_discrete_sample`, called by the caller, which holds its buffer: no array enters
    the step, whose every array argument would cost reference counting at every step).
    Returns (x+, acc+, mem+, Out at t_k).
    """
    fl = flags_nb(variant)
    if fl.ext and lp.ext_hold:  # a held input is constant over the step: its value after t_k
        inp = layout.Inp(inp.r0, inp.r1, inp.r2, inp.rv, inp.l0, inp.l1, inp.l2, inp.e1,
                         inp.e1, inp.e1)
    extras = fl.extras
    ns = lp.ns if extras else 0.0  # no digital controller (a constant at each call site)
    delta = 1.0 if fl.fric_m == FRIC_LUGRE1 else lp.delta  # every lane's exponent (pow_nb folds)
    t = k * dt
    wgt = 0.5 * dt if (k == 0 or k == n_steps) else dt
    hw = 0.5 * dt  # the jump contact's regularisation band (model.transmission)
    # --- LuGre bristle steps (exact for frozen speed), held over the RK4 stages
    if fl.lugre_m:
        zb, tb = bristle_step_nb(x.z, x.w_m, dt, lp.Fc, lp.Fs, lp.vs, delta, lp.sigma0,
                                 lp.sigma1)
        fr = lp.friction != 0.0
        z_new = zb if fr else 0.0
        tf_b = tb if fr else 0.0
        visc = lp.sigma2 if fr else 0.0
    else:
        z_new = 0.0
        tf_b = 0.0
        visc = 0.0
    if fl.lugre_L:
        zl_new, tf_bl = bristle_step_nb(x.z_L, x.w_L, dt, lp.Fc_L, lp.Fs_L, lp.vs_L, lp.delta_L,
                                        lp.sigma0_L, lp.sigma1_L)
    else:
        zl_new = 0.0
        tf_bl = 0.0
    # --- controller at t_k (digital: sample, hold, integrate)
    zh_next = mem.zh
    tfh = 0.0
    if extras and fl.ctrl == CTRL_PAPER and lp.ff_sigma0 > 0.0:
        # the friction observer's bristle state, advanced like the plant's (held)
        w_meas0 = controller_nb(x, inp.r0, lp, fl, mem.xn2, 0.0)[1]
        zh_next, tfh = bristle_step_nb(mem.zh, w_meas0, dt, lp.ff_fc, max(lp.ff_fs, lp.ff_fc),
                                       lp.ff_vs, delta, lp.ff_sigma0, lp.ff_sigma1)
    th_meas, w_meas, e_w, u_unsat, u_dem, u_pre = controller_nb(x, inp.r0, lp, fl, mem.xn2, tfh)
    xn1_next, xn2_next = mem.xn1, mem.xn2
    if extras and fl.ctrl == CTRL_PAPER and lp.nw > 0.0:
        xn1_next, xn2_next = notch_update_nb(mem.xn1, mem.xn2, u_pre, lp.nw, lp.notch_zeta, dt)
    disc = ns > 0.0
    sample = disc and mem.cnt == 0.0
    uh = mem.uh
    x_i = x.xI
    if fl.ctrl == CTRL_PAPER:
        uh = u_dem if sample else uh
        x_i = integral_update_nb(x.xI, e_w, u_unsat, lp.sat2, lp.Ts) if sample else x.xI
    elif fl.ctrl == CTRL_DISCRETE and sample:
        uh = dsc
    cnt = ns - 1.0 if sample else mem.cnt - 1.0
    stuck_m = site_on(fl, 0) and mem.stuck_m != 0.0  # only a static site sticks
    stuck_l = site_on(fl, 1) and mem.stuck_L != 0.0
    u_sel = command_nb(u_dem, uh, disc, inp.e0, lp, fl)
    u_out, u_amp = amplifier_input_nb(u_sel, lp, fl, True)
    t_shaft = shaft_nb(x, lp, fl, hw)
    (t_drive, f_drive, t_fric_m, t_load, f_fric_l, f_rigid, f_other_m,
     f_other_l) = plant_nb(x, u_amp, t_shaft, inp.l0, inp.e0, lp, fl, tf_b, visc, tf_bl, stuck_m,
                           mem.dir_m, stuck_l, mem.dir_L)
    if fl.hybrid:  # the static friction recorded: slip friction, or what a stuck site holds
        if fl.rigid:
            f_fric_l = f_other_l - f_rigid if not stuck_l else f_other_l
        else:
            if fl.static_m and stuck_m:
                t_fric_m = f_other_m
            if fl.static_L and stuck_l:
                f_fric_l = f_other_l
    # --- metrics (trapezoid weights over the full-resolution samples)
    e = inp.r0 - x.theta_L
    ev = inp.rv - x.w_L
    act = lp.is_step and t >= lp.t_step
    cur = x.i if not fl.amp and fl.ctrl != CTRL_NONE else (
        inp.e0 if (fl.ctrl == CTRL_NONE and lp.plant_input == 2.0)
        else (t_drive / lp.Kt if lp.Kt > 0.0 else 0.0))
    st = Step(e, ev, abs(e), abs(ev), wgt, t, float(k), in_ss, in_osc, act,
              x.theta_L / lp.step, cur, u_out, x.w_L, t_shaft)
    acc = accumulate(acc, st)
    out = Out(u_out, u_amp, t_shaft, t_fric_m, t_load, f_drive, f_fric_l, cur)
    # --- RK4 step (reference, load profile and input signal at the stage times; bristle
    # torques, held command, notch and observer states held)
    xs = layout.set_xI(x, x_i)
    integrate = advance_for(variant)  # the variant's integrator (RK4, or the switch search)
    xn, stuck_m, dir_m, stuck_l, dir_l = integrate(
        xs, dt, inp, lp, fl, uh, disc, mem.xn2, tfh, tf_b, visc, tf_bl, stuck_m, mem.dir_m,
        stuck_l, mem.dir_L, hw)
    xn = layout.set_z(xn, z_new)
    if fl.lugre_L:
        xn = layout.set_z_L(xn, zl_new)
    if not fl.amp:
        xn = layout.set_i(xn, min(max(xn.i, -lp.sat3), lp.sat3))
    if fl.rigid:  # the motor follows the load
        xn = motor_follows(xn, lp)
    ok = (abs(xn.w_m) < W_RUNAWAY and abs(xn.theta_L) < THETA_RUNAWAY
          and abs(xn.i) < I_RUNAWAY and abs(xn.theta_m) < _INF and abs(xn.w_L) < _INF
          and abs(xn.xI) < _INF and abs(z_new) < _INF
          and (not fl.amp_bw or abs(xn.f_amp) < _INF) and (not fl.lugre_L or abs(zl_new) < _INF)
          and (not fl.trans or abs(xn.f_t) < _INF))
    dies = mem.alive != 0.0 and not ok and k < n_steps
    kend = k + 1.0 if dies else mem.kend
    alive = 0.0 if dies else mem.alive
    mem = layout.Mem(cnt, uh, alive, kend, xn1_next, xn2_next, zh_next,
                     1.0 if stuck_m else 0.0, dir_m, 1.0 if stuck_l else 0.0, dir_l)
    return xn, acc, mem, out


@njit(cache=True, forceinline=True, error_model="numpy")
def discrete_sample(W, j, x, inp, mem, lp, variant):
    """The discrete cascade's command from this sample on (``model.discrete``; its buffer in
    rows of ``W[:, j]``) when it samples at this step, else the held one."""
    fl = flags_nb(variant)
    if fl.ctrl != CTRL_DISCRETE or mem.cnt != 0.0:
        return mem.uh
    th_meas, w_meas = controller_nb(x, inp.r0, lp, fl, mem.xn2, 0.0)[:2]
    taps = (lp.dc_fir0, lp.dc_fir1, lp.dc_fir2, lp.dc_fir3, lp.dc_fir4, lp.dc_fir5, lp.dc_fir6,
            lp.dc_fir7)
    return discrete_sample_nb(W[_BUF0:_BUF0 + BUFFER, j], th_meas, w_meas * lp.inv_m, inp.r0,
                              lp.Ts, lp.dc_kp, lp.dc_ki, lp.dc_vmax, lp.dc_kv, lp.dc_kvi,
                              lp.dc_umax, lp.dc_vsrc, lp.dc_ndiff, taps, lp.a_vf, lp.dc_delay)


@njit(cache=True, forceinline=True, error_model="numpy")
def advance_nb(W, k, dt, n_steps, in_ss, in_osc, record_now, variant):
    """One time step of every lane of a chunk (the lane loop the compiler vectorises)."""
    for j in range(W.shape[1]):
        x = load_x(W, j)
        acc = load_acc(W, j)
        mem = load_mem(W, j)
        lp = lane_params(W, j)
        inp = load_inp(W, j)
        dsc = 0.0
        if flags_nb(variant).ctrl == CTRL_DISCRETE:
            dsc = discrete_sample(W, j, x, inp, mem, lp, variant)
        xn, acc, mem, out = step_nb(x, acc, mem, inp, lp, k, dt, n_steps, in_ss, in_osc, variant,
                                  dsc)
        if record_now:
            record(W, j, x, inp, out, lp)
        store_x(W, j, xn)
        store_acc(W, j, acc)
        store_mem(W, j, mem)


@njit(cache=True, forceinline=True, error_model="numpy")
def init_nb(W, n_real, step_info, qidx, dt, n_steps):
    """Fill the derived rows, memory, states and accumulators of every lane of ``W`` (the spare
    lanes beyond ``n_real`` copy lane 0's parameters)."""
    for j in range(W.shape[1]):
        jj = j if j < n_real else 0
        for c in range(N_PARAMS):
            W[_P0 + c, j] = W[_P0 + c, jj]
        W[R.inv_m, j] = 1.0 / W[R.m, j]
        W[R.inv_L, j] = 1.0 / W[R.L, j]
        W[R.inv_Jm, j] = 1.0 / W[R.Jm, j]
        W[R.inv_JL, j] = 1.0 / W[R.JL, j]
        m = W[R.m, j]
        W[R.inv_Jtot, j] = 1.0 / (W[R.JL, j] + m * m * W[R.Jm, j])
        W[R.contact, j] = 1.0 if W[R.damping, j] == 0.0 else 0.0
        tau = W[R.contact_tau, j]
        W[R.inv_tau, j] = 1.0 / tau if tau > 0.0 else _INF
        hc = W[R.contact_hc, j]
        W[R.hck, j] = hc / W[R.contact_pen, j] if hc > 0.0 else 0.0
        qp = W[R.q_pos, j]
        qs = W[R.q_speed, j]
        W[R.inv_qp, j] = 1.0 / qp if qp > 0.0 else 0.0
        W[R.inv_qs, j] = 1.0 / qs if qs > 0.0 else 0.0
        if W[R.notch_hz, j] > 0.0:
            W[R.nw, j], W[R.nc, j] = notch_gain_nb(W[R.notch_hz, j],
                                                     W[R.notch_depth, j],
                                                     W[R.notch_zeta, j])
        else:
            W[R.nw, j], W[R.nc, j] = 0.0, 0.0
        W[R.t_const, j] = W[R.T_load, j] - W[R.offset, j]
        r0, alpha = W[R.R, j], W[R.alpha_cu, j]
        W[R.th_r0, j] = r0 * (1.0 + alpha * (W[R.T_amb, j] - W[R.T_ref, j]))
        W[R.th_ra, j] = r0 * alpha
        W[R.th_gwh, j] = 1.0 / W[R.Rth_wh, j]
        W[R.th_gha, j] = 1.0 / W[R.Rth_ha, j]
        W[R.th_icw, j] = 1.0 / W[R.Cth_w, j]
        W[R.th_ich, j] = 1.0 / W[R.Cth_h, j]
        at = W[R.amp_tau, j]
        W[R.inv_amp_tau, j] = 1.0 / at if at > 0.0 else 0.0
        ts = W[R.Ts, j]
        W[R.a_vf, j] = filter_coefficient_nb(W[R.dc_vfc, j], ts)
        W[R.ns, j] = np.floor(ts / dt + 0.5) if ts > 0.0 else 0.0
        for r in range(_MEM0, _STATE0):  # memory and the cascade's buffer
            W[r, j] = 0.0
        W[R.alive, j] = 1.0
        W[R.kend, j] = n_steps + 1.0  # the step it diverged at (never, unless set)
        wm0 = W[R.x0_w_m, j]
        wl0 = W[R.x0_w_L, j]
        W[R.stuck_m, j] = 1.0 if wm0 == 0.0 else 0.0  # a static site at rest starts stuck
        W[R.dir_m, j] = -1.0 if wm0 < 0.0 else 1.0
        W[R.stuck_L, j] = 1.0 if wl0 == 0.0 else 0.0
        W[R.dir_L, j] = -1.0 if wl0 < 0.0 else 1.0
        init_x(W, j, _XINIT)  # the initial state (model.params.INITIAL_STATE)
        q = qidx[jj]
        W[R.is_step, j] = step_info[q, 0]
        W[R.step, j] = step_info[q, 1]
        W[R.t_step, j] = step_info[q, 2]
        init_acc(W, j)


@njit(cache=True, error_model="numpy")
def finish_metrics_nb(W, n_real, dt, n_steps, k_ss, met, rows):
    """Turn the accumulators of the first ``n_real`` lanes into met[rows[j], :] (SI)."""
    duration = n_steps * dt
    ss_n = n_steps + 1 - k_ss
    for j in range(n_real):
        out = met[rows[j]]
        if W[R.alive, j] == 0.0:
            for c in range(N_METRICS):
                out[c] = _NAN
            out[MI.diverged] = 1.0
            out[MI.t_end] = W[R.kend, j] * dt
            continue
        a = load_acc(W, j)
        out[MI.iae_pos] = a.iae
        out[MI.ise_pos] = a.ise
        out[MI.itae_pos] = a.itae
        out[MI.rms_pos] = np.sqrt(a.ise / duration)
        out[MI.max_pos] = a.emax
        out[MI.iae_vel] = a.iaev
        out[MI.ise_vel] = a.isev
        out[MI.itae_vel] = a.itaev
        out[MI.rms_vel] = np.sqrt(a.isev / duration)
        out[MI.max_vel] = a.evmax
        out[MI.ss_err_pos] = a.ss / ss_n
        out[MI.p2p_pos] = a.emax_o - a.emin_o
        out[MI.p2p_vel] = a.evmax_o - a.evmin_o
        out[MI.peak_current] = a.pki
        out[MI.peak_voltage] = a.pku
        out[MI.peak_load_rate] = a.pkwl
        out[MI.peak_torque] = a.pkt
        out[MI.diverged] = 0.0
        out[MI.t_end] = duration
        if W[R.is_step, j] != 0.0:
            t_step = W[R.t_step, j]
            out[MI.overshoot] = max(0.0, a.smax - 1.0) * 100.0
            out[MI.rise_time] = a.t90 - a.t10
            out[MI.t50] = a.t50 - t_step
            out[MI.step_peak] = a.smax
            out[MI.settling_time] = ((a.last_out + 1.0) * dt - t_step if a.last_out < n_steps
                                        else _NAN)
        else:
            out[MI.overshoot] = _NAN
            out[MI.rise_time] = _NAN
            out[MI.t50] = _NAN
            out[MI.step_peak] = _NAN
            out[MI.settling_time] = _NAN

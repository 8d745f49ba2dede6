"""The actuator's algebra: from the state and the inputs to every force (numba, one definition).

The chain, in order (docs/model.md §2; each element an equation of its own module)::

    sensors -> controller (paper cascade + compensators | the discrete cascade's held command |
    the input signal) -> (+ disturbance) -> amplifier dead zone -> drive (armature or amplifier)
    -> transmission (compliant: shaft torque; rigid: none) -> friction (motor, load) -> the net
    force on each body

:func:`algebra_nb` evaluates it once, for the kernel's step (at the sample instant) and for
every RK4 stage alike: the compensator chain is written here and nowhere else. Its results
(:data:`ALG`) are what the state equations (``model.states``) read by name.

The structure of an actuator is a *variant*: a whole number whose bits say which elements it
has (:func:`variant_code`, :func:`flags_nb`). The kernel is compiled once per variant, with the
variant a compile-time constant, so a variant carries only the code its elements need.
"""

from __future__ import annotations

from collections import namedtuple

from ema_cli._numba import njit
from ema_cli.model.controller import (
    cascade_nb,
    deadzone_inverse_nb,
    friction_ff_nb,
    sensors_nb,
)
from ema_cli.model.drive import amplifier_output_nb
from ema_cli.model.elements import dead_zone_nb, saturate_nb
from ema_cli.model.friction import slip_friction_nb
from ema_cli.model.plant import load_torque_nb
from ema_cli.model.transmission import preload_torque_nb, shaft_torque_nb

# ---- variants ----------------------------------------------------------------------------
FRIC_NONE, FRIC_LUGRE1, FRIC_LUGRE, FRIC_STATIC = 0, 1, 2, 3
"""Motor friction codes: none, LuGre with the Stribeck exponent 1, LuGre with any exponent,
the static law (``model.friction``)."""
LFRIC_NONE, LFRIC_LUGRE, LFRIC_STATIC = 0, 1, 2
CTRL_PAPER, CTRL_DISCRETE, CTRL_NONE = 0, 1, 2
B_EXTRAS, B_RIGID, B_AMP, B_AMP_BW, B_FRIC_L, B_CTRL, B_EXT, B_TRANS = 2, 3, 4, 5, 6, 8, 10, 11
B_THERMAL = 12
"""Bit positions in a variant code: motor friction (bits 0-1), extras (the paper cascade's
sampling, quantisers, compensators), rigid, amplifier, amplifier bandwidth, load friction
(bits 6-7), controller (bits 8-9), the input signal read (a disturbance or the actuation), the
transmission's friction or preload, the thermal element (``model.thermal``)."""
PAPER_MASK = (1 << B_RIGID) - 1
"""Variant codes below this are the paper's EMA (compliant, armature, motor LuGre, the paper
cascade): the seven codes the kernel had before actuator descriptions."""

FLAGS = ("fric_m", "extras", "rigid", "amp", "amp_bw", "fric_L", "ctrl", "ext", "hybrid",
         "lugre_m", "lugre_L", "static_m", "static_L", "trans", "thermal")
Flags = namedtuple("Flags", FLAGS)  # type: ignore[misc]
"""The structure of a variant, decoded (every field a compile-time constant in the kernel)."""


@njit(cache=True, forceinline=True, error_model="numpy")
def flags_nb(variant):
    """Decode a variant code into :class:`Flags`."""
    fric_m = variant & 3
    fric_l = (variant >> B_FRIC_L) & 3
    ctrl = (variant >> B_CTRL) & 3
    static_m = fric_m == FRIC_STATIC
    static_l = fric_l == LFRIC_STATIC
    return Flags(fric_m, (variant >> B_EXTRAS) & 1 != 0, (variant >> B_RIGID) & 1 != 0,
                 (variant >> B_AMP) & 1 != 0, (variant >> B_AMP_BW) & 1 != 0, fric_l, ctrl,
                 (variant >> B_EXT) & 1 != 0, static_m or static_l,
                 FRIC_LUGRE1 <= fric_m <= FRIC_LUGRE, fric_l == LFRIC_LUGRE,
                 static_m, static_l, (variant >> B_TRANS) & 1 != 0,
                 (variant >> B_THERMAL) & 1 != 0)


def flags_of(code: int) -> Flags:
    """:func:`flags_nb` from Python (compiled or not: ``NUMBA_DISABLE_JIT``)."""
    return Flags(*getattr(flags_nb, "py_func", flags_nb)(int(code)))


def describe_variant(code: int) -> str:
    """A reader's words for a variant code."""
    code = int(code)
    fric = {0: "no friction", 1: "LuGre (exponent 1)", 2: "LuGre", 3: "static friction"}
    parts = [fric[code & 3]]
    if (code >> B_EXTRAS) & 1:
        parts.append("extras")
    if code >> B_RIGID:
        extra = []
        if (code >> B_RIGID) & 1:
            extra.append("rigid")
        if (code >> B_AMP) & 1:
            extra.append("amplifier" + (" with bandwidth" if (code >> B_AMP_BW) & 1 else ""))
        lf = (code >> B_FRIC_L) & 3
        if lf:
            extra.append({1: "load LuGre", 2: "load static friction"}[lf])
        ctrl = (code >> B_CTRL) & 3
        if ctrl:
            extra.append({1: "discrete cascade", 2: "plant only"}[ctrl])
        if (code >> B_EXT) & 1:
            extra.append("input signal")
        if (code >> B_TRANS) & 1:
            extra.append("transmission friction/preload")
        if (code >> B_THERMAL) & 1:
            extra.append("thermal")
        parts.extend(extra)
    return ", ".join(parts)


# ---- the algebra ---------------------------------------------------------------------------
ALG = ("th_meas", "w_meas", "e_w", "u_unsat", "u_dem", "u_pre", "u_cmd", "u_amp", "t_shaft",
       "t_drive", "f_drive", "t_fric_m", "t_load", "f_fric_L", "f_rigid", "f_other_m",
       "f_other_L", "stuck_m", "stuck_L", "disc", "l_prof", "tf_b", "visc")
"""The algebra's results (:func:`algebra_nb`), SI, load side in the axis's units: measured
position and motor speed, the speed error, the PI output before and after its limit, the
compensated demand before the notch, the command sent (after the hold and the dead-zone
inverse, before the amplifier dead zone), the amplifier input, the shaft torque, the drive's
torque on the motor and force on the axis (load side), the motor friction, the external torque
on the load (offset included), the load friction, the net force on a rigid axis, the forces on
each body other than its static friction, whether each static-friction site sticks, and whether
the paper cascade is sampled (its integral then advances at the samples, not continuously), and
three inputs the state equations read themselves: the load profile, the motor's held LuGre
bristle torque and viscous coefficient."""
Alg = namedtuple("Alg", ALG)  # type: ignore[misc]


@njit(cache=True, forceinline=True, error_model="numpy")
def controller_nb(x, r, prm, fl, xn2, tfh):
    """The sensors and the paper cascade with its compensators at state ``x`` and reference
    ``r`` -> ``(th_meas, w_meas, e_w, u_unsat, u_dem, u_pre)``: measured position and motor
    speed, speed error, the PI output before and after its limit (notch included), the
    compensated demand before the notch (0 for the other controllers, which are sampled by the
    step: ``model.discrete``). ``xn2`` the notch state, ``tfh`` the friction observer's held
    bristle torque."""
    extras = fl.extras
    q_pos = prm.q_pos if extras else 0.0  # no quantisers (a constant at each call site)
    q_speed = prm.q_speed if extras else 0.0
    th_meas, w_meas = sensors_nb(x.theta_L, x.w_m, prm.d4, prm.d3, q_pos, q_speed, prm.inv_qp,
                                 prm.inv_qs, x.theta_m * prm.inv_m, prm.fb_motor)
    e_w = 0.0
    u_unsat = 0.0
    u_dem = 0.0
    u_pre = 0.0
    if fl.ctrl == CTRL_PAPER:
        e_w, u_unsat, u_dem = cascade_nb(r, th_meas, w_meas, x.xI, prm.m, prm.Kpp, prm.Kps,
                                         prm.Kis, prm.sat1, prm.sat2)
        if extras:  # friction compensation, then the notch (held state)
            t_ff = (tfh + prm.ff_sigma2 * w_meas if prm.ff_sigma0 > 0.0
                    else friction_ff_nb(e_w + w_meas, w_meas, prm.ff_fc, prm.ff_fs, prm.ff_vs,
                                        prm.delta, prm.ff_sigma2, prm.ff_band))
            u_pre = u_unsat + prm.R / prm.Kt * t_ff
            u_unsat = u_pre + prm.nc * xn2
            u_dem = saturate_nb(u_unsat, prm.sat2)
    return th_meas, w_meas, e_w, u_unsat, u_dem, u_pre


@njit(cache=True, forceinline=True, error_model="numpy")
def command_nb(u_dem, uh, disc, ext, prm, fl):
    """The command the controller sends: the paper cascade's demand (``disc``: the one held
    since its last sample, ``uh``), the discrete cascade's held command ``uh``, or the input
    signal ``ext`` (controller none, drive command); plus the input signal as a disturbance
    when ``dist_out``."""
    if fl.ctrl == CTRL_PAPER:
        u_sel = uh if disc else u_dem
    elif fl.ctrl == CTRL_DISCRETE:
        u_sel = uh
    else:
        u_sel = ext if prm.plant_input == 0.0 else 0.0
    if fl.ext and fl.ctrl != CTRL_NONE:
        u_sel = u_sel + ext  # a disturbance added to the controller's output
    return u_sel


@njit(cache=True, forceinline=True, error_model="numpy")
def shaft_nb(x, prm, fl, hw):
    """The transmission's shaft torque at state ``x`` (``model.transmission``; 0 on a rigid
    axis, which has no shaft state)."""
    if fl.rigid:
        return 0.0
    dth = x.theta_m * prm.inv_m - x.theta_L
    t = shaft_torque_nb(prm.kL, prm.alpha, prm.c, prm.contact, prm.inv_tau, prm.contact_hc,
                        prm.hck, dth, x.w_m * prm.inv_m - x.w_L, hw)
    if fl.trans:  # the transmission's friction (a Dahl element) and the anti-backlash preload
        t = t + x.f_t
        if prm.preload > 0.0:
            t = t + preload_torque_nb(prm.preload, prm.alpha, dth)
    return t


@njit(cache=True, forceinline=True, error_model="numpy")
def amplifier_input_nb(u_sel, prm, fl, at_sample):
    """The command sent (0 with the motor locked; the dead-zone inverse) and the amplifier's
    input after its dead zone -> ``(u_cmd, u_amp)``. ``at_sample`` zeroes the locked motor's
    command before the inverse (the step's instant: the command recorded), otherwise its
    amplifier input after it (the RK4 stages): equal values, two orders of operations that the
    kernel has always used, kept so that the compiled arithmetic stays the same bit for bit."""
    if at_sample:
        u_cmd = 0.0 if prm.locked else u_sel
        if fl.extras:
            u_cmd = deadzone_inverse_nb(u_cmd, prm.dzi_v, prm.dzi_band)
        return u_cmd, dead_zone_nb(u_cmd, prm.d1)
    u = u_sel
    if fl.extras:
        u = deadzone_inverse_nb(u, prm.dzi_v, prm.dzi_band)
    return u, 0.0 if prm.locked else dead_zone_nb(u, prm.d1)


@njit(cache=True, forceinline=True, error_model="numpy")
def plant_nb(x, u_amp, t_shaft, l_prof, ext, prm, fl, tf_b, visc, tf_bl, stuck_m, dir_m,
             stuck_l, dir_l):
    """From the amplifier's input ``u_amp`` (:func:`amplifier_input_nb`) and the shaft torque
    ``t_shaft`` (:func:`shaft_nb`) to every force -> ``(t_drive, f_drive, t_fric_m, t_load,
    f_fric_l, f_rigid, f_other_m, f_other_l)`` (:data:`ALG`)."""
    # the drive: torque on the motor, force on the axis (load side)
    if fl.ctrl == CTRL_NONE and prm.plant_input == 1.0:  # the input is the force on the load
        f_drive = ext
        t_drive = ext * prm.inv_m
    elif fl.ctrl == CTRL_NONE and prm.plant_input == 2.0:  # the input is the current
        t_drive = prm.Kt * ext
        f_drive = prm.m * t_drive
    elif fl.amp:
        f_drive = amplifier_output_nb(x.f_amp, u_amp, prm.amp_gain, prm.amp_limit, fl.amp_bw)
        t_drive = f_drive * prm.inv_m
    else:
        t_drive = prm.Kt * x.i
        # (m*Kt)*i, not m*t_drive: a second use of Kt*i would keep the compiler from fusing it
        # into the motor's equation, and the paper's EMA would change in its last bits
        f_drive = (prm.m * prm.Kt) * x.i
    t_load = load_torque_nb(x.theta_L, prm.t_const, l_prof, prm.k_h)
    # friction at the motor: LuGre (held bristle torque + viscous) or the static law in slip
    if fl.static_m:
        t_fric_m = (slip_friction_nb(x.w_m, dir_m, prm.Fc, prm.Fc_neg, prm.Fs, prm.Fs_neg,
                                     prm.vs, prm.delta, prm.sigma2, prm.sigma2_neg)
                    if not stuck_m and not fl.rigid else 0.0)
    else:  # LuGre, or none: tf_b = visc = 0 (computed all the same: the paper's EMA's last bits)
        t_fric_m = tf_b + visc * x.w_m
    if fl.lugre_L:
        f_fric_l = tf_bl + prm.Fv_L * x.w_L
    elif fl.static_L and not stuck_l and not fl.rigid:
        f_fric_l = slip_friction_nb(x.w_L, dir_l, prm.Fc_L, prm.Fc_L_neg, prm.Fs_L,
                                    prm.Fs_L_neg, prm.vs_L, prm.delta_L, prm.Fv_L, prm.Fv_L_neg)
    else:
        f_fric_l = 0.0
    f_rigid = 0.0
    f_other_m = 0.0
    f_other_l = 0.0
    if fl.rigid:
        # one body in load coordinates; its static sites' friction combined (model.friction)
        f_other_l = (f_drive - prm.m * (prm.bm * x.w_m + t_fric_m) - prm.bL * x.w_L + t_load
                     - f_fric_l)
        f_static = 0.0
        if fl.hybrid and not stuck_l:
            f_static = rigid_slip_friction_nb(x.w_L, dir_l, prm)
        f_rigid = f_other_l - f_static
    else:
        if fl.static_m:
            f_other_m = t_drive - prm.bm * x.w_m - t_shaft * prm.inv_m
        if fl.static_L:
            f_other_l = t_shaft - prm.bL * x.w_L + t_load
    return t_drive, f_drive, t_fric_m, t_load, f_fric_l, f_rigid, f_other_m, f_other_l


@njit(cache=True, forceinline=True, error_model="numpy")
def rigid_slip_friction_nb(v, d, prm):
    """The static friction of a rigid axis slipping at load speed ``v`` in direction ``d``:
    the motor site's (at ``m*v``, times ``m``) and the load site's, each when its law is the
    static one (``friction``/``friction_L`` = 2)."""
    f = 0.0
    if prm.friction == 2.0:
        f += prm.m * slip_friction_nb(prm.m * v, d, prm.Fc, prm.Fc_neg, prm.Fs, prm.Fs_neg,
                                      prm.vs, prm.delta, prm.sigma2, prm.sigma2_neg)
    if prm.friction_L == 2.0:
        f += slip_friction_nb(v, d, prm.Fc_L, prm.Fc_L_neg, prm.Fs_L, prm.Fs_L_neg, prm.vs_L,
                              prm.delta_L, prm.Fv_L, prm.Fv_L_neg)
    return f


@njit(cache=True, forceinline=True, error_model="numpy")
def breakaway_nb(prm, fl, site):
    """``(Fs_+, Fs_-)``: the breakaway band of a static site (``site`` 0 the motor, 1 the load;
    a rigid axis's one body is site 1, its sites' bands combined)."""
    if fl.rigid:
        fp = 0.0
        fn = 0.0
        if prm.friction == 2.0:
            fp += prm.m * prm.Fs
            fn += prm.m * prm.Fs_neg
        if prm.friction_L == 2.0:
            fp += prm.Fs_L
            fn += prm.Fs_L_neg
        return fp, fn
    if site == 0:
        return prm.Fs, prm.Fs_neg
    return prm.Fs_L, prm.Fs_L_neg


@njit(cache=True, forceinline=True, error_model="numpy")
def algebra_nb(x, r, l_prof, ext, prm, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m,
               dir_m, stuck_l, dir_l, hw):
    """Every algebraic quantity of the actuator (:data:`ALG`) at state ``x`` (the kernel's
    state tuple), reference ``r``, load profile ``l_prof`` and input signal ``ext`` (at the same
    instant), for the lane's parameters ``prm`` and the variant's :class:`Flags` ``fl``:
    :func:`controller_nb`, :func:`command_nb`, :func:`plant_nb`.

    Held over a step by the caller: ``uh`` the sampled controller command (``disc``: a digital
    paper cascade, or the discrete cascade), ``xn2`` the notch state, ``tfh`` the friction
    observer's bristle torque, ``tf_b``/``visc`` the motor's LuGre bristle torque and viscous
    coefficient, ``tf_bl`` the load's LuGre bristle torque, the static sites' modes
    (``stuck_*`` True while stuck, ``dir_*`` the slip direction +-1). ``hw`` the contact's
    regularisation band (``model.transmission``)."""
    th_meas, w_meas, e_w, u_unsat, u_dem, u_pre = controller_nb(x, r, prm, fl, xn2, tfh)
    u_sel = command_nb(u_dem, uh, disc, ext, prm, fl)
    u_cmd, u_amp = amplifier_input_nb(u_sel, prm, fl, False)
    t_shaft = shaft_nb(x, prm, fl, hw)
    (t_drive, f_drive, t_fric_m, t_load, f_fric_l, f_rigid, f_other_m,
     f_other_l) = plant_nb(x, u_amp, t_shaft, l_prof, ext, prm, fl, tf_b, visc, tf_bl, stuck_m,
                           dir_m, stuck_l, dir_l)
    return Alg(th_meas, w_meas, e_w, u_unsat, u_dem, u_pre, u_cmd, u_amp, t_shaft, t_drive,
               f_drive, t_fric_m, t_load, f_fric_l, f_rigid, f_other_m, f_other_l,
               stuck_m, stuck_l, disc, l_prof, tf_b, visc)

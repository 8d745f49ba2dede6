"""Integrating one step of one lane: RK4 over the state table, and the switches of static
friction located inside the step (numba, inlined into the kernel).

:func:`_rk4` advances the ``rk4`` states of ``model.states.STATES`` (their equations bound by
name, ``sim.layout.variant_rates``) with the inputs at the step's start, middle and end and
everything else held. A variant with static friction (``model.friction``) advances instead with
:func:`hybrid_advance`: a site sticks with its speed exactly 0 and breaks away when the other
forces on its body leave its breakaway band; a slipping site whose speed reaches 0 sticks or
reverses. The instant of every switch is located inside the step by regula falsi (Illinois) on
RK4 sub-steps from the step's start, the inputs interpolated quadratically through the step's
three samples (:func:`_quad`), so the integration stays fourth order across the switches.
The step calls :data:`advance_for`, which picks one of the two when the variant is typed; each
is compiled once per ``sim.variants.rates_key`` (the variants that share a key share it).
"""

from __future__ import annotations

from typing import Any

from numba import config, types
from numba.extending import intrinsic

from ema_cli._numba import njit
from ema_cli.model.actuator import (
    Alg,
    amplifier_input_nb,
    breakaway_nb,
    command_nb,
    controller_nb,
    flags_of,
    plant_nb,
    shaft_nb,
)
from ema_cli.model.friction import holds_nb
from ema_cli.sim import layout
from ema_cli.sim.layout import variant_combine, variant_rates, variant_stage
from ema_cli.sim.variants import rates_key

MAX_EVENTS = 8  # friction switches located in one step at most (more: the rest in its mode)
EVENT_ITERATIONS = 60  # regula-falsi iterations locating one switch at most [-]
EVENT_TOL = 1e-13  # a switch's instant is located to this fraction of the step [-]


@njit(cache=True, forceinline=True, error_model="numpy")
def _stage_rates(x, r, lprof, ext, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m,
                 dir_m, stuck_l, dir_l, hw, variant):
    """The state equations' rates at one RK4 stage (``sim.layout.rates``: every ``rk4`` state of
    ``model.states.STATES``, its arguments bound by name to the state, the algebra, the lane's
    parameters and the variant's flags)."""
    if fl.rigid:  # the motor follows the load at every stage (its own rates are held)
        x = motor_follows(x, lp)
    th_meas, w_meas, e_w, u_unsat, u_dem, u_pre = controller_nb(x, r, lp, fl, xn2, tfh)
    u_sel = command_nb(u_dem, uh, disc, ext, lp, fl)
    u_cmd, u_amp = amplifier_input_nb(u_sel, lp, fl, False)
    t_shaft = shaft_nb(x, lp, fl, hw)
    (t_drive, f_drive, t_fric_m, t_load, f_fric_l, f_rigid, f_other_m,
     f_other_l) = plant_nb(x, u_amp, t_shaft, lprof, ext, lp, fl, tf_b, visc, tf_bl, stuck_m,
                           dir_m, stuck_l, dir_l)
    alg = Alg(th_meas, w_meas, e_w, u_unsat, u_dem, u_pre, u_cmd, u_amp, t_shaft, t_drive,
              f_drive, t_fric_m, t_load, f_fric_l, f_rigid, f_other_m, f_other_l, stuck_m,
              stuck_l, disc, lprof, tf_b, visc)
    return variant_rates(x, alg, lp, variant)


@njit(cache=True, forceinline=True, error_model="numpy")
def rk4(x, h, ra, rb, rc, la, lb, lc, ea, eb, ec, lp, fl, uh, disc, xn2, tfh, tf_b, visc,
         tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw, variant):
    """One RK4 step of size ``h`` from ``x`` (inputs at its start, middle and end: ``ra, rb,
    rc`` the reference, ``l*`` the load profile, ``e*`` the input signal; everything else held)
    -> the state at its end (the non-rk4 states unchanged)."""
    k1 = _stage_rates(x, ra, la, ea, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m,
                      dir_m, stuck_l, dir_l, hw, variant)
    x2 = variant_stage(x, 0.5 * h, k1, variant)
    k2 = _stage_rates(x2, rb, lb, eb, lp, fl, uh, disc, xn2, tfh, tf_b,
                      visc, tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw, variant)
    x3 = variant_stage(x, 0.5 * h, k2, variant)
    k3 = _stage_rates(x3, rb, lb, eb, lp, fl, uh, disc, xn2, tfh, tf_b,
                      visc, tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw, variant)
    x4 = variant_stage(x, h, k3, variant)
    k4 = _stage_rates(x4, rc, lc, ec, lp, fl, uh, disc, xn2, tfh, tf_b, visc,
                      tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw, variant)
    return variant_combine(x, h / 6.0, k1, k2, k3, k4, variant)


@njit(cache=True, forceinline=True, error_model="numpy")
def _quad(y0, y1, y2, s):
    """The quadratic through ``(0, y0), (1/2, y1), (1, y2)`` at ``s`` (a fraction of the step):
    an input between its three samples of the step."""
    return y0 + s * ((-3.0 * y0 + 4.0 * y1 - y2) + s * (2.0 * y0 - 4.0 * y1 + 2.0 * y2))


@njit(cache=True, forceinline=True, error_model="numpy")
def _sub_rk4(x, s0, s1, h, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
             stuck_l, dir_l, hw, variant):
    """An RK4 sub-step from the fraction ``s0`` of the step to ``s1`` (step ``h``), the inputs
    interpolated through the step's samples (:func:`_quad`)."""
    sm = 0.5 * (s0 + s1)
    return rk4(x, (s1 - s0) * h,
                _quad(inp.r0, inp.r1, inp.r2, s0), _quad(inp.r0, inp.r1, inp.r2, sm),
                _quad(inp.r0, inp.r1, inp.r2, s1),
                _quad(inp.l0, inp.l1, inp.l2, s0), _quad(inp.l0, inp.l1, inp.l2, sm),
                _quad(inp.l0, inp.l1, inp.l2, s1),
                _quad(inp.e0, inp.e1, inp.e2, s0), _quad(inp.e0, inp.e1, inp.e2, sm),
                _quad(inp.e0, inp.e1, inp.e2, s1),
                lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw,
                variant)


@njit(cache=True, forceinline=True, error_model="numpy")
def _site_speed(x, fl, site):
    """The speed of a static site's body (``site`` 0 the motor, 1 the load or rigid axis)."""
    return x.w_m if site == 0 else x.w_L


@njit(cache=True, forceinline=True, error_model="numpy")
def _other_force(x, s, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
                 stuck_l, dir_l, hw, site):
    """The forces on a static site's body other than its static friction, at state ``x`` and
    the fraction ``s`` of the step."""
    r = _quad(inp.r0, inp.r1, inp.r2, s)
    lprof = _quad(inp.l0, inp.l1, inp.l2, s)
    ext = _quad(inp.e0, inp.e1, inp.e2, s)
    if fl.rigid:
        x = motor_follows(x, lp)
    th_meas, w_meas, e_w, u_unsat, u_dem, u_pre = controller_nb(x, r, lp, fl, xn2, tfh)
    u_sel = command_nb(u_dem, uh, disc, ext, lp, fl)
    u_amp = amplifier_input_nb(u_sel, lp, fl, False)[1]
    out = plant_nb(x, u_amp, shaft_nb(x, lp, fl, hw), lprof, ext, lp, fl, tf_b, visc, tf_bl,
                   stuck_m, dir_m, stuck_l, dir_l)
    return out[6] if site == 0 else out[7]


@njit(cache=True, forceinline=True, error_model="numpy")
def _event_value(x, s, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
                 stuck_l, dir_l, hw, site, stuck, d):
    """The switching function of a site (> 0: it has switched): a slipping site's speed against
    its direction, ``-d*v``; a stuck site's excess over its breakaway band."""
    if not stuck:
        return -d * _site_speed(x, fl, site)
    f = _other_force(x, s, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
                     stuck_l, dir_l, hw, site)
    fp, fn = breakaway_nb(lp, fl, site)
    return max(f - fp, -fn - f)


@njit(cache=True, forceinline=True, error_model="numpy")
def _switching(x, s, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
               stuck_l, dir_l, hw):
    """The switching function of the step (> 0: a site has switched): the largest of the
    sites' (:func:`_event_value`) -> (value, that site; -1 when no site has static friction)."""
    g = -1.0
    first = -1
    for site in (0, 1):
        if not site_on(fl, site):
            continue
        gs = _event_value(x, s, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m,
                          dir_m, stuck_l, dir_l, hw, site, stuck_m if site == 0 else stuck_l,
                          dir_m if site == 0 else dir_l)
        if first < 0 or gs > g:
            g, first = gs, site
    return g, first


@njit(cache=True, forceinline=True, error_model="numpy")
def _breakaways(x, s0, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
                stuck_l, dir_l, hw):
    """The stuck sites whose band the other forces already leave at ``s0`` (a sampled command
    can jump): they break away there -> the modes."""
    for site in (0, 1):
        if not site_on(fl, site) or not (stuck_m if site == 0 else stuck_l):
            continue
        f = _other_force(x, s0, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m,
                         dir_m, stuck_l, dir_l, hw, site)
        fp, fn = breakaway_nb(lp, fl, site)
        if not holds_nb(f, fp, fn):
            if site == 0:
                stuck_m, dir_m = False, (1.0 if f > 0.0 else -1.0)
            else:
                stuck_l, dir_l = False, (1.0 if f > 0.0 else -1.0)
    return stuck_m, dir_m, stuck_l, dir_l


@njit(cache=True, error_model="numpy")
def hybrid_advance(x, h, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
                   stuck_l, dir_l, hw, variant):
    """Advance a state with static friction sites over one step ``h``, locating every switch
    inside it: -> (state, stuck_m, dir_m, stuck_l, dir_l). A site that sticks at the step's
    start breaks away there if the (possibly just sampled) forces already leave its band.

    Each part of the step (from the start or the last switch to the end) is one search with one
    RK4 sub-step per trial (one call site, so the variant compiles one RK4, not three): the
    whole part first; when the switching function (:func:`_switching`) is positive at its end,
    regula falsi (Illinois) for the instant it crosses 0."""
    s0 = 0.0
    for ev in range(MAX_EVENTS + 1):
        stuck_m, dir_m, stuck_l, dir_l = _breakaways(x, s0, inp, lp, fl, uh, disc, xn2, tfh,
                                                     tf_b, visc, tf_bl, stuck_m, dir_m,
                                                     stuck_l, dir_l, hw)
        a, ga = s0, 0.0
        g0, site0 = _switching(x, s0, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl,
                               stuck_m, dir_m, stuck_l, dir_l, hw)
        b, gb, xb, first = 1.0, 1.0, x, -1
        if g0 > 0.0 and ev < MAX_EVENTS:  # switched at the start already (rounding)
            b, first = s0, site0
        else:
            ga = g0
            s = 1.0
            side = 0
            for it in range(EVENT_ITERATIONS + 1):
                xs = _sub_rk4(x, s0, s, h, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl,
                              stuck_m, dir_m, stuck_l, dir_l, hw, variant)
                gs, site = _switching(xs, s, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc,
                                      tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw)
                if it == 0:
                    if not gs > 0.0 or ev == MAX_EVENTS:  # no switch (or no more allowed)
                        return xs, stuck_m, dir_m, stuck_l, dir_l
                    b, gb, xb, first = s, gs, xs, site
                elif gs > 0.0:
                    b, gb, xb, first = s, gs, xs, site
                    if side == -1:
                        ga *= 0.5
                    side = -1
                else:
                    a, ga = s, gs
                    if side == 1:
                        gb *= 0.5
                    side = 1
                if b - a <= EVENT_TOL:
                    break
                s = (a * gb - b * ga) / (gb - ga) if gb != ga else 0.5 * (a + b)
                if not a < s < b:
                    s = 0.5 * (a + b)
        # the switch of site `first` at b: a slipping site stops (speed exactly 0) and sticks
        # or reverses; a stuck site breaks away
        x = xb
        stuck = stuck_m if first == 0 else stuck_l
        if not stuck:
            x = _with_speed(x, first, 0.0)
            if fl.rigid:
                x = _with_speed(x, 0, 0.0)
        f = _other_force(x, b, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m,
                         dir_m, stuck_l, dir_l, hw, first)
        fp, fn = breakaway_nb(lp, fl, first)
        hold = (not stuck) and holds_nb(f, fp, fn)
        nd = 1.0 if f > 0.0 else -1.0
        if first == 0:
            stuck_m, dir_m = hold, (dir_m if hold else nd)
        else:
            stuck_l, dir_l = hold, (dir_l if hold else nd)
        s0 = b
        if s0 >= 1.0:
            return x, stuck_m, dir_m, stuck_l, dir_l
    return x, stuck_m, dir_m, stuck_l, dir_l


@njit(cache=True, forceinline=True, error_model="numpy")
def motor_follows(x, lp):
    """A rigid axis's state with the motor's angle and speed ``m`` times the load's."""
    return layout.set_w_m(layout.set_theta_m(x, lp.m * x.theta_L), lp.m * x.w_L)


@njit(cache=True, forceinline=True, error_model="numpy")
def _with_speed(x, site, v):
    """``x`` with the speed of a site's body set to ``v``."""
    return layout.set_w_m(x, v) if site == 0 else layout.set_w_L(x, v)


@njit(cache=True, forceinline=True, error_model="numpy")
def site_on(fl, site):
    """Whether a variant has a static-friction site 0 (the motor of a compliant axis) or 1 (the
    load of a compliant axis, or a rigid axis's one body)."""
    if site == 0:
        return fl.static_m and not fl.rigid
    return fl.static_L or (fl.rigid and fl.hybrid)


def _make_advance(key: int) -> Any:
    """The integrator of the variants whose ``sim.variants.rates_key`` is ``key``, compiled
    once for all of them: :func:`hybrid_advance` when the key has static friction, else
    :func:`rk4` with the modes unchanged. Arguments: (x, h, inp, lp, fl, uh, disc, xn2, tfh,
    tf_b, visc, tf_bl, stuck_m, dir_m, stuck_l, dir_l, hw) as :func:`hybrid_advance`'s; returns
    (state, stuck_m, dir_m, stuck_l, dir_l)."""
    if flags_of(key).hybrid:
        def advance(x, h, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,  # noqa: ANN001, ANN202
                    stuck_l, dir_l, hw):
            return hybrid_advance(x, h, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl,
                                  stuck_m, dir_m, stuck_l, dir_l, hw, key)
    else:
        def advance(x, h, inp, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,  # noqa: ANN001, ANN202
                    stuck_l, dir_l, hw):
            return (rk4(x, h, inp.r0, inp.r1, inp.r2, inp.l0, inp.l1, inp.l2, inp.e0, inp.e1,
                        inp.e2, lp, fl, uh, disc, xn2, tfh, tf_b, visc, tf_bl, stuck_m, dir_m,
                        stuck_l, dir_l, hw, key), stuck_m, dir_m, stuck_l, dir_l)
    return njit(cache=True, forceinline=True, error_model="numpy")(advance)


_ADVANCE: dict[int, Any] = {}


def _advance_for_py(variant: int) -> Any:
    """The integrator (:func:`_make_advance`) of the kernel's ``variant``."""
    key = rates_key(int(variant))
    if key not in _ADVANCE:
        _ADVANCE[key] = _make_advance(key)
    return _ADVANCE[key]


@intrinsic
def _advance_for_nb(typingctx, variant):  # noqa: ANN001, ANN202 (numba's intrinsic API)
    if not isinstance(variant, types.IntegerLiteral):
        return None
    disp = _advance_for_py(variant.literal_value)

    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        return context.get_dummy_value()
    return types.Dispatcher(disp)(variant), codegen


advance_for = _advance_for_py if config.DISABLE_JIT else _advance_for_nb
"""The integrator of a kernel variant (a compile-time constant in compiled code): one step from
the state at its start -> (state, stuck_m, dir_m, stuck_l, dir_l). Chosen when the variant is
typed, compiled once per ``sim.variants.rates_key`` (the variants that share a key share it), so
a variant without static friction never compiles the switch search."""

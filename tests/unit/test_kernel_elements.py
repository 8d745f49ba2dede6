"""model/ elements, transmission and LuGre update vs hand-computed values and fine integration."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ema_cli.model.elements import dead_zone_nb as _dz
from ema_cli.model.elements import quantize_nb
from ema_cli.model.elements import saturate_nb as _sat
from ema_cli.model.lugre import bristle_step_nb, steady_friction_nb
from ema_cli.model.params import INDEX, resolve, to_row
from ema_cli.model.transmission import hc_gain, inverse_tau, shaft_torque, shaft_torque_nb


def row(**over) -> np.ndarray:
    return np.array(to_row(resolve(over)))


def _shaft_torque(p, dth, dw):
    return shaft_torque_nb(p[INDEX["kL"]], p[INDEX["alpha"]], p[INDEX["c"]],
                           p[INDEX["damping"]] == 0.0, inverse_tau(p[INDEX["contact_tau"]]),
                           p[INDEX["contact_hc"]],
                           hc_gain(p[INDEX["contact_hc"]], p[INDEX["contact_pen"]]), dth, dw, 0.0)


def _bristle_step(p, z, w, dt):
    return bristle_step_nb(z, w, dt, *(p[INDEX[k]] for k in
                                       ("Fc", "Fs", "vs", "delta", "sigma0", "sigma1")))


@pytest.mark.parametrize(("u", "q", "expected"), [
    (0.26, 0.1, 0.3), (-0.26, 0.1, -0.3), (0.24, 0.1, 0.2), (0.05, 0.1, 0.1), (0.3, 0.0, 0.3),
])
def test_quantizer(u, q, expected):
    # q*floor(u/q + 1/2): 0.26/0.1 + 0.5 = 3.1 -> 3 -> 0.3; q = 0 is the identity
    assert quantize_nb(u, q, 1.0 / q if q else 0.0) == pytest.approx(expected, abs=1e-15)


def test_array_torque_equals_scalar_torque():
    # the array helper used by identification and figures is the kernel's function, sample by
    # sample (exact equality: same compiled arithmetic)
    rng = np.random.default_rng(3)
    dth, dw = rng.normal(0, 0.005, 500), rng.normal(0, 1.0, 500)
    for form in ("contact", "paper"):
        for tau in (0.0, 1e-4):
            arr = shaft_torque(dth, dw, 590.0, 0.003, 0.8, form, tau)
            ref = [shaft_torque_nb(590.0, 0.003, 0.8, form == "contact", inverse_tau(tau),
                                   0.0, 0.0, a, b, 0.0) for a, b in zip(dth, dw, strict=True)]
            assert np.array_equal(arr, np.array(ref))


def test_hunt_crossley_share():
    # h = 1, tau = 0: T = kL*pen*(1 + lam*dpen/dt), lam = c/(kL*pen_ref), pushing only; both
    # contact sides (dpen/dt = +dw above the gap, -dw below); h = 0.5 halfway; h = 0 exact
    kL, a, c, pr = 590.0, 0.003, 0.8, 1e-3
    lam = c / (kL * pr)
    for dth, dw in ((0.0045, 0.3), (0.0045, -0.3), (-0.0052, -0.4), (-0.0052, 0.2)):
        pen = abs(dth) - a
        dpen = dw if dth > 0 else -dw
        hc = math.copysign(1.0, dth) * max(kL * pen * (1.0 + lam * dpen), 0.0)
        lin = math.copysign(1.0, dth) * max(kL * pen + c * dpen, 0.0)
        got = shaft_torque(np.array([dth]), np.array([dw]), kL, a, c, "contact", 0.0, 1.0, pr)
        assert got[0] == pytest.approx(hc, rel=1e-12)
        half = shaft_torque(np.array([dth]), np.array([dw]), kL, a, c, "contact", 0.0, 0.5, pr)
        g = 0.5 + 0.5 * pen / pr
        ref = math.copysign(1.0, dth) * max(kL * pen + c * g * dpen, 0.0)
        assert half[0] == pytest.approx(ref, rel=1e-12)
        zero = shaft_torque(np.array([dth]), np.array([dw]), kL, a, c, "contact", 0.0, 0.0, pr)
        assert zero[0] == pytest.approx(lin, rel=1e-15)
    # continuous at contact entry: at pen -> 0 the HC torque -> 0 whatever the closing speed
    tiny = shaft_torque(np.array([a + 1e-12]), np.array([5.0]), kL, a, c, "contact", 0.0, 1.0)
    assert abs(tiny[0]) < 1e-8


def test_jump_contact_band_by_hand():
    # tau = 0 with hw > 0 (the kernel passes dt/2): on a closing contact the damping's weight
    # rises linearly across |pen| <= hw*|dw|, pushing only; opening and tau > 0 are untouched
    kL, a, c, hw = 590.0, 0.003, 0.8, 5e-6
    inf = inverse_tau(0.0)

    def tq(dth, dw, inv_tau=inf, h=hw):
        return shaft_torque_nb(kL, a, c, True, inv_tau, 0.0, 0.0, dth, dw, h)

    dw = 2.0  # closing on the + side: half band 1e-5 rad
    half = hw * dw
    assert tq(a - 1.0001 * half, dw) == 0.0  # before the band: the gap
    assert tq(a - 0.5 * half, dw) == pytest.approx(c * 0.25 * dw, rel=1e-12)  # damping only
    assert tq(a, dw) == pytest.approx(c * 0.5 * dw, rel=1e-12)  # half weight at the touch
    assert tq(a + 0.5 * half, dw) == pytest.approx(kL * 0.5 * half + c * 0.75 * dw, rel=1e-12)
    assert tq(a + 2 * half, dw) == kL * (2 * half) + c * dw  # past the band: the exact law
    # - side, closing (dw < 0): the mirror image
    assert tq(-a, -dw) == pytest.approx(-c * 0.5 * dw, rel=1e-12)
    assert tq(-(a + 2 * half), -dw) == -(kL * (2 * half) + c * dw)
    # opening: the exact jump law (no band), clamped so that it never pulls
    assert tq(a - 0.5 * half, -dw) == 0.0
    assert tq(a + 0.5 * half, -dw) == max(kL * 0.5 * half - c * dw, 0.0)
    # the band is at most alpha/2 (the two sides never meet)
    assert tq(0.4 * a, 1e6) == 0.0
    assert tq(0.5 * a + 1e-12, 1e6) > 0.0
    # hw = 0 and tau > 0: the unregularised law, bit for bit
    rng = np.random.default_rng(5)
    for dth, w in zip(rng.normal(0, 0.005, 300), rng.normal(0, 1.0, 300), strict=True):
        assert tq(dth, w, h=0.0) == shaft_torque(np.array([dth]), np.array([w]), kL, a, c,
                                                 "contact", 0.0)[0]
        assert tq(dth, w, inverse_tau(1e-4)) == shaft_torque(
            np.array([dth]), np.array([w]), kL, a, c, "contact", 1e-4)[0]


@pytest.mark.parametrize(("u", "d", "expected"), [
    (0.5, 0.2, 0.3), (-0.5, 0.2, -0.3), (0.1, 0.2, 0.0), (-0.2, 0.2, 0.0),
    (0.7, 0.0, 0.7), (-0.7, 0.0, -0.7), (0.0, 0.0, 0.0),
])
def test_dead_zone(u, d, expected):
    assert _dz(u, d) == pytest.approx(expected, abs=1e-15)


@pytest.mark.parametrize(("u", "lim", "expected"), [
    (50.0, 40.0, 40.0), (-50.0, 40.0, -40.0), (12.5, 40.0, 12.5), (1e9, math.inf, 1e9),
])
def test_saturation(u, lim, expected):
    assert _sat(u, lim) == expected


def test_backlash_paper_form():
    # Eq. 2 literally: T = kL*DZ(dth, alpha) + c*dw, c acting inside the gap too.
    p = row(kL=590.0, alpha=0.003, c=0.8, damping="paper")
    assert _shaft_torque(p, 0.005, 0.1) == pytest.approx(590 * 0.002 + 0.8 * 0.1)
    assert _shaft_torque(p, -0.004, 0.0) == pytest.approx(590 * -0.001)
    assert _shaft_torque(p, 0.001, 0.5) == pytest.approx(0.8 * 0.5)  # in the gap: damping only


def test_backlash_contact_form():
    # Contact: 0 inside the gap; in contact T may push but never pull.
    p = row(kL=590.0, alpha=0.003, c=0.8, damping="contact")
    assert _shaft_torque(p, 0.001, 0.5) == 0.0
    assert _shaft_torque(p, 0.005, 0.1) == pytest.approx(590 * 0.002 + 0.8 * 0.1)  # 1.26 N*m
    # separating fast: 590*0.002 + 0.8*(-3) = -1.22 < 0 -> clamped to 0 (no pull)
    assert _shaft_torque(p, 0.005, -3.0) == 0.0
    assert _shaft_torque(p, -0.005, 3.0) == 0.0
    assert _shaft_torque(p, -0.005, -0.1) == pytest.approx(-590 * 0.002 - 0.8 * 0.1)


def test_no_backlash_is_a_linear_shaft_in_both_forms():
    for form in ("contact", "paper"):
        p = row(kL=590.0, alpha=0.0, c=0.8, damping=form)
        assert _shaft_torque(p, 0.001, -3.0) == pytest.approx(590 * 0.001 - 0.8 * 3.0)


def lugre_row(sigma2=0.01):
    return row(friction=1, sigma2=sigma2)


@pytest.mark.parametrize("w", [-50.0, -2.0, -0.3, 0.05, 1.0, 7.0, 200.0])
def test_lugre_steady_state_friction(w):
    # For constant w the bristle settles at z_ss = g(w)*sign(w)/sigma0, so
    # Tf = g(w)*sign(w) + sigma2*w with g(w) = Fc + (Fs - Fc)*exp(-|w/vs|^delta).
    p = lugre_row()
    dt = 1e-5
    z = 0.0
    for _ in range(200_000):
        z, tf_bristle = _bristle_step(p, z, w, dt)
    fc, fs = p[INDEX["Fc"]], p[INDEX["Fs"]]
    g = fc + (fs - fc) * math.exp(-abs(w / p[INDEX["vs"]]) ** p[INDEX["delta"]])
    expected = g * math.copysign(1.0, w) + p[INDEX["sigma2"]] * w
    assert tf_bristle + p[INDEX["sigma2"]] * w == pytest.approx(expected, rel=1e-9)
    steady = steady_friction_nb(w, fc, fs, p[INDEX["vs"]], p[INDEX["delta"]], p[INDEX["sigma2"]])
    assert steady == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("w", "z0"), [(0.5, 0.0), (-3.0, 1e-4), (20.0, -1e-3), (1e-6, 2e-5)])
def test_lugre_exact_update_matches_fine_integration(w, z0):
    # One step of the exact update vs Radau at rtol 1e-12 of dz/dt = w - sigma0*|w|/g(w)*z,
    # and the held bristle torque vs the time average of sigma0*z + sigma1*dz/dt.
    p = lugre_row()
    dt = 1e-5
    sig0, sig1 = p[INDEX["sigma0"]], p[INDEX["sigma1"]]
    fc, fs = p[INDEX["Fc"]], p[INDEX["Fs"]]
    g = fc + (fs - fc) * math.exp(-abs(w / p[INDEX["vs"]]))
    a = sig0 * abs(w) / g

    def rhs(_t, y):
        z = y[0]
        return [w - a * z, z]  # z and its integral

    sol = solve_ivp(rhs, (0, dt), [z0, 0.0], method="Radau", rtol=1e-12, atol=1e-18)
    z_ref, int_z = sol.y[0, -1], sol.y[1, -1]
    tf_ref = sig0 * int_z / dt + sig1 * (z_ref - z0) / dt
    z1, tf = _bristle_step(p, z0, w, dt)
    assert z1 == pytest.approx(z_ref, rel=1e-9, abs=1e-15)
    assert tf == pytest.approx(tf_ref, rel=1e-7, abs=1e-12)

"""The thermal element's closed forms: the two-node network's exact flow (``duty.thermal``,
``model.thermal.flow_nb``) against the modal solution written out here, the S3 permissible
overload factor against IEC 60034-1's single-time-constant formula, and the reference EMA's
continuous current (its defaults: the rated 6.07 A at 40 degC ambient and class F)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from ema_cli.acceptance.duty.thermal import Network, flow
from ema_cli.model.params import resolve
from ema_cli.model.thermal import continuous_current, time_constants
from tests.helpers.thermal import closed_form as _closed_form

ZERO_C = 273.15


def _network(**kw: float) -> Network:
    p = {**resolve(), "alpha_cu": 0.0, **kw}
    return Network.of(p)


def test_two_node_step_response_matches_the_closed_form() -> None:
    """Constant losses (alpha 0): 10 W into the winding of the reference EMA's network, the
    exact flow composed over 400 uneven steps across 10 slow time constants; winding and
    housing within 0.01 K of the closed form at every step (they reach ~40 K and ~29 K)."""
    net = _network()
    amb = 40.0 + ZERO_C
    tau_slow = time_constants(resolve())[1]
    rng = np.random.default_rng(3)
    h = rng.uniform(0.2, 1.8, 400)
    h *= 10.0 * tau_slow / h.sum()
    x = np.array([amb, amb])
    got = []
    for hk in h:
        e, f = flow(net, 10.0 / net.r0, 0.0, amb, float(hk))  # i^2 with i^2 R0 = 10 W
        x = e @ x + f
        got.append(x.copy())
    t = np.cumsum(h)
    want = _closed_form(net, 10.0, t, amb)
    err = np.abs(np.array(got).T - want)
    assert want[0, -1] - amb == pytest.approx(10.0 * (1.2 + 2.93), rel=1e-4)
    assert err.max() < 0.01, err.max()


def test_s3_overload_factor_single_time_constant() -> None:
    """S3 intermittent duty on a one-time-constant body (the housing's capacity negligible:
    1e-6 of the winding's): the current factor k over the continuous current that brings the
    periodic steady state's peak to the continuous rise, found by root finding on the exact
    flow over a period, against sqrt((1 - e^(-T/tau)) / (1 - e^(-t_on/tau))) within 0.5 %,
    for four duty factors and periods."""
    net = _network(Cth_w=300.0, Cth_h=300.0e-6)
    tau = (1.0 / net.g_wh + 1.0 / net.g_ha) * net.c_w
    amb = 40.0 + ZERO_C
    rise = 100.0
    i2_cont = rise / (net.r0 * (1.0 / net.g_wh + 1.0 / net.g_ha))  # S1: the rise at the limit

    def peak(k: float, t_on: float, period: float) -> float:
        e_on, f_on = flow(net, k * k * i2_cont, 0.0, amb, t_on)
        e_off, f_off = flow(net, 0.0, 0.0, amb, period - t_on)
        # periodic steady state at the end of the on-time: x = E_on (E_off x + f_off) + f_on
        m = e_on @ e_off
        x = np.linalg.solve(np.eye(2) - m, e_on @ f_off + f_on)
        return float(x[0]) - amb

    for t_on, period in ((60.0, 600.0), (150.0, 600.0), (300.0, 1200.0), (20.0, 100.0)):
        k = brentq(lambda s, a=t_on, b=period: peak(s, a, b) - rise, 1.0, 20.0, xtol=1e-12)
        want = math.sqrt((1 - math.exp(-period / tau)) / (1 - math.exp(-t_on / tau)))
        assert k == pytest.approx(want, rel=0.005), (t_on, period, k, want)
        assert k > 1.05


def test_reference_ema_continuous_current_is_its_rating() -> None:
    """The defaults: at 40 degC ambient and class F (155 degC) the constant current whose
    steady winding temperature is the limit, i^2 R(155 degC) (R_wh + R_ha) = 115 K, solved
    here by hand, is the reference EMA's rated 6.07 A (within 0.5 %); model.thermal's function
    agrees to rounding."""
    p = resolve()
    assert p["T_amb"] == pytest.approx(40.0 + ZERO_C)
    r_hot = p["R"] * (1 + 0.00393 * (155.0 - 25.0))
    i_cont = math.sqrt(115.0 / (r_hot * (p["Rth_wh"] + p["Rth_ha"])))
    assert i_cont == pytest.approx(6.07, rel=0.005)
    assert continuous_current(p, 155.0 + ZERO_C) == pytest.approx(i_cont, rel=1e-12)
    assert continuous_current(p, 155.0 + ZERO_C, 160.0 + ZERO_C) == 0.0

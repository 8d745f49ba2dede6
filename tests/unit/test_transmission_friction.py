"""The transmission's friction (a Dahl element) and anti-backlash preload
(``model.transmission``), against closed forms and scipy."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from ema_cli.errors import EmaError
from ema_cli.model.params import resolve
from ema_cli.model.transmission import dahl_path, friction_rate_nb, preload_torque_nb


def test_dahl_path_from_rest_is_the_closed_form_exponential():
    fc, sig = 0.4, 600.0
    th = np.linspace(0.0, 5e-3, 501)
    f = dahl_path(th, fc, sig)
    np.testing.assert_allclose(f, fc * (1.0 - np.exp(-sig * th / fc)), rtol=0, atol=1e-14)


def test_dahl_path_equals_the_rate_equation_integrated_along_a_loop():
    """The path update (exact between samples) against the kernel's own rate function
    integrated by scipy over a twist that goes up, down and up again."""
    fc, sig = 0.3, 250.0
    t = np.linspace(0.0, 3.0, 3001)
    th = 6e-3 * np.sin(2 * math.pi * t / 2.0) + 1e-3 * t  # twist [rad], two reversals

    def rhs(tt, y):
        dw = (6e-3 * 2 * math.pi / 2.0 * math.cos(2 * math.pi * tt / 2.0) + 1e-3)
        return [friction_rate_nb.py_func(dw, 0.0, 1.0, y[0], fc, sig, True)]

    sol = solve_ivp(rhs, (0.0, 3.0), [0.0], t_eval=t, rtol=1e-11, atol=1e-14, method="DOP853")
    f = dahl_path(th, fc, sig)
    # the path update is exact for a twist monotonic between samples: away from the two
    # reversals the sampled path is; at them the error is that of one sample's chord
    assert np.max(np.abs(f - sol.y[0])) < 2e-4 * fc
    # the loop: loaded and unloaded branches 2*Fc apart once saturated
    assert f.max() == pytest.approx(fc, rel=1e-3) and f.min() == pytest.approx(-fc, rel=1e-3)


def test_preload_is_linear_through_the_gap_and_constant_in_contact():
    a, p = 2e-3, 0.5
    for dth, want in ((0.0, 0.0), (1e-3, 0.25), (-1e-3, -0.25), (2e-3, 0.5), (5e-3, 0.5),
                      (-9e-3, -0.5)):
        assert preload_torque_nb.py_func(p, a, dth) == pytest.approx(want, abs=1e-15)


def test_transmission_friction_defaults_and_refusals():
    v = resolve({"Fc_t": 0.3})
    assert v["sigma_t"] == v["kL"]
    with pytest.raises(EmaError, match="'preload'.*needs a half backlash alpha > 0"):
        resolve({"preload": 0.1})
    with pytest.raises(EmaError, match="need a compliant transmission"):
        resolve({"Fc_t": 0.3, "rigid": 1, "kL": 590.0})

"""The linear limit (analysis/linear.py) against three independent references: the hand-written
state space of tests/system/test_linear_reference.py, the nonlinear simulator with every
nonlinearity off (a reference step and a load-torque step), and python-control's margins."""

from __future__ import annotations

import control
import numpy as np
import pytest

from ema_cli.analysis.linear import linear_model, loop_transfer, margins
from ema_cli.errors import EmaError
from ema_cli.model.params import resolve
from ema_cli.sim.signals import InputSignal
from ema_cli.units import DEG
from tests.helpers.batch import LINEAR_OVERRIDES, run_rows
from tests.helpers.linear import linear_ss

VARIANTS = [{}, {"kL": 300.0, "Kpp": 80.0}, {"Kps": 0.3, "Kis": 4.0, "zeta_t": 0.05},
            {"k_h": 50.0, "bL": 0.1}, {"fb_motor": 1.0}, {"fb_motor": 0.4, "kL": 200.0}]


@pytest.mark.parametrize("extra", VARIANTS)
def test_reference_response_equals_the_hand_written_model(extra):
    p = resolve({**LINEAR_OVERRIDES, **extra})
    hand = linear_ss(p) if not (extra.get("k_h") or extra.get("fb_motor")) else None
    lm = linear_model(p)
    f = np.geomspace(0.1, 500, 60)
    ours = lm.response(f, "theta_ref", "theta_L")
    ref = control.ss(lm.A, lm.B[:, :1], lm.C[:1], lm.D[:1, :1])
    np.testing.assert_allclose(ours, np.squeeze(control.frequency_response(ref, 2 * np.pi * f)
                                                 .complex), rtol=1e-10)
    if hand is not None:  # the same A and B, derived twice
        np.testing.assert_allclose(lm.A, hand.A, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(lm.B[:, 0], np.squeeze(hand.B), rtol=1e-12)


@pytest.mark.parametrize("fb", [0.0, 0.5, 1.0])
def test_reference_step_matches_the_simulator(fb):
    # fb: the position fed back, (1-fb)*theta_L + fb*theta_m/m (controller.position_feedback)
    p = resolve({**LINEAR_OVERRIDES, "fb_motor": fb, "kL": 250.0})
    step = 0.1 * DEG
    res = run_rows([p], InputSignal("step", step), duration=0.4, dt=1e-5, output_interval=1e-4)
    lm = linear_model(p)
    sys = control.ss(lm.A, lm.B[:, :1], lm.C[:1], lm.D[:1, :1])
    ref = np.squeeze(control.step_response(sys, T=res.t_out).outputs) * step
    assert np.max(np.abs(res.signal("theta_load") - ref)) < 1e-6 * step


def test_load_torque_step_matches_the_simulator():
    torque = 5.0  # N*m on the load from t = 0, reference 0
    p = resolve({**LINEAR_OVERRIDES, "T_load": torque, "k_h": 20.0})
    res = run_rows([p], InputSignal("step", 0.0), duration=0.4, dt=1e-5, output_interval=1e-4)
    lm = linear_model(p)
    sys = control.ss(lm.A, lm.B[:, 1:], lm.C, lm.D[:, 1:])
    out = control.step_response(sys, T=res.t_out).outputs[:, 0, :] * torque
    k = lm.outputs.index("theta_L")
    scale = np.max(np.abs(out[k]))
    assert scale > 0
    assert np.max(np.abs(res.signal("theta_load") - out[k])) < 1e-6 * scale
    i = lm.outputs.index("i")
    assert np.max(np.abs(res.signal("current") - out[i])) < 1e-6 * np.max(np.abs(out[i]))


@pytest.mark.parametrize("extra", VARIANTS)
@pytest.mark.parametrize("loop", ["position", "speed"])
def test_margins_equal_python_control(extra, loop):
    p = resolve({**LINEAR_OVERRIDES, **extra})
    ours = margins(p, loop)
    lm = linear_model(p, loop)
    gm, pm, wcg, wcp = control.margin(-control.ss(lm.A, lm.B, lm.C, lm.D))
    assert ours.pm_deg == pytest.approx(pm, abs=1e-6)
    assert ours.f_pm_hz == pytest.approx(wcp / (2 * np.pi), rel=1e-6)
    if np.isfinite(ours.gm_db):
        assert ours.gm_db == pytest.approx(20 * np.log10(gm), abs=1e-6)
        assert ours.f_gm_hz == pytest.approx(wcg / (2 * np.pi), rel=1e-6)
    else:  # no phase crossover in 1 mHz..100 kHz: python-control finds none that matters
        assert not np.isfinite(gm) or gm > 1e6 or wcg / (2 * np.pi) > 1e5


def test_motor_feedback_moves_the_transmission_out_of_the_loop():
    # with the loop closed on the motor angle, the position loop's margins no longer see the
    # load resonance, and a stiffer or softer transmission changes them far less
    soft, stiff = ({**LINEAR_OVERRIDES, "kL": k} for k in (150.0, 2000.0))
    on_load = [margins(resolve(p), "position").pm_deg for p in (soft, stiff)]
    on_motor = [margins(resolve({**p, "fb_motor": 1.0}), "position").pm_deg
                for p in (soft, stiff)]
    assert abs(on_motor[0] - on_motor[1]) < 0.2 * abs(on_load[0] - on_load[1])


def test_the_loop_transfer_closes_to_the_closed_loop():
    # T(s) = L/(1+L) for the position loop (unity feedback at the measured load angle)
    p = resolve(LINEAR_OVERRIDES)
    f = np.geomspace(0.1, 200, 40)
    L = loop_transfer(p, "position", f)
    closed = linear_model(p).response(f, "theta_ref", "theta_L")
    np.testing.assert_allclose(closed, L / (1 + L), rtol=1e-9)


def test_bad_loops_and_parameters():
    with pytest.raises(EmaError, match="loop must be one of"):
        linear_model(resolve(), "current")
    with pytest.raises(EmaError, match="finite L > 0"):
        linear_model({**resolve(), "L": float("inf")})

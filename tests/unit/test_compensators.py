"""Compensators of the controller (issue 11, part 1): each element against hand-computed
values, the notch in the simulator against the linear model (python-control), and the effect of
each compensator on the paper's scenarios with true and 20 %-off estimates."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from ema_cli.analysis.linear import linear_model, margins
from ema_cli.config.loader import load_config, resolve_run
from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.model.controller import (
    deadzone_inverse_nb,
    friction_ff_nb,
    notch_gain_nb,
    notch_update_nb,
)
from ema_cli.model.params import resolve
from ema_cli.sim.signals import InputSignal
from ema_cli.sim.tables import MET
from ema_cli.units import DEG
from tests.helpers.batch import LINEAR_OVERRIDES, run_rows


def test_deadzone_inverse_by_hand():
    assert deadzone_inverse_nb(2.0, 1.0, 0.02) == 3.0
    assert deadzone_inverse_nb(-2.0, 1.0, 0.02) == -3.0
    assert deadzone_inverse_nb(0.01, 1.0, 0.02) == pytest.approx(0.51)  # inside the band
    assert deadzone_inverse_nb(0.7, 0.0, 0.02) == 0.7  # off


def test_friction_compensation_by_hand():
    # Coulomb 0.02, static 0.03, vs 1 rad/s, delta 1, sigma2 0.1, band 0.5 rad/s
    w_cmd, w_meas = 2.0, 1.5
    expect = (0.02 + 0.01 * math.exp(-2.0)) * 1.0 + 0.1 * 1.5
    assert friction_ff_nb(w_cmd, w_meas, 0.02, 0.03, 1.0, 1.0, 0.1, 0.5) == pytest.approx(expect)
    # inside the band the Coulomb part is ramped: w_cmd = 0.1 -> 0.2 of it
    got = friction_ff_nb(0.1, 0.0, 0.02, 0.03, 1.0, 1.0, 0.0, 0.5)
    assert got == pytest.approx((0.02 + 0.01 * math.exp(-0.1)) * 0.2)
    assert friction_ff_nb(-3.0, -3.0, 0.02, 0.0, 1.0, 1.0, 0.0, 0.5) == -0.02  # no Stribeck


def test_discrete_notch_has_the_continuous_gain():
    # the Tustin update driven by a sine at the notch centre: gain `depth` (-20 dB), and 1 far
    # away; from the state-space form y = u + c*x2
    f0, depth, zeta, h = 40.0, 0.1, 0.5, 1e-5
    w, c = notch_gain_nb(f0, depth, zeta)
    for f, expect in ((f0, depth), (0.4, 1.0), (4000.0, 1.0)):
        n = int(round(20 / f / h)) if f < 100 else int(round(200 / f / h))
        t = np.arange(n) * h
        u = np.sin(2 * np.pi * f * t)
        x1 = x2 = 0.0
        y = np.empty(n)
        for k in range(n):
            y[k] = u[k] + c * x2
            x1, x2 = notch_update_nb(x1, x2, u[k], w, zeta, h)
        last = y[n // 2:]
        assert (last.max() - last.min()) / 2 == pytest.approx(expect, rel=2e-3, abs=2e-3)


def test_simulator_with_notch_equals_the_linear_model():
    p = resolve({**LINEAR_OVERRIDES, "notch_hz": 30.0, "notch_depth": 0.2, "notch_zeta": 0.4,
                 "ff_sigma2": 0.05, "friction": 1, "sigma2": 0.05, "Fc": 1e-12})
    step = 0.1 * DEG
    res = run_rows([p], InputSignal("step", step), duration=0.4, dt=1e-5, output_interval=1e-4)
    lm = linear_model(p)
    assert lm.A.shape == (8, 8)
    sys = control.ss(lm.A, lm.B[:, :1], lm.C[:1], lm.D[:1, :1])
    ref = np.squeeze(control.step_response(sys, T=res.t_out).outputs) * step
    # the notch states advance once per step (held over the RK4 stages): first order in dt
    assert np.max(np.abs(res.signal("theta_load") - ref)) < 1e-3 * step


def run(rows, amplitude_deg=0.1, duration=1.0):
    res = run_rows([resolve(r) for r in rows], InputSignal("step", amplitude_deg * DEG),
                   duration=duration, dt=1e-5, output_interval=None, parallel=True)
    return res.metrics


def test_deadzone_inverse_on_the_paper_scenario():
    # amplifier dead zone 1 V, 0.1 deg step: 0.593 s to settle uncompensated
    m = run([{"d1": 1.0}, {"d1": 1.0, "dzi_v": 1.0}, {"d1": 1.0, "dzi_v": 0.8},
             {"d1": 1.0, "dzi_v": 1.2}])
    settle, iae = m[:, MET["settling_time"]], m[:, MET["iae_pos"]]
    assert settle[0] == pytest.approx(0.593, abs=0.002)
    assert settle[1] <= 0.25
    assert np.all(iae[2:] <= 0.75 * iae[0])  # 20 % off either way: IAE >= 25 % lower
    base = margins(resolve({"d1": 1.0}), "position")
    comp = margins(resolve({"d1": 1.0, "dzi_v": 1.0}), "position")
    assert comp.gm_db == pytest.approx(base.gm_db) and comp.gm_db >= 6 and comp.pm_deg >= 45


def test_motor_feedback_on_the_dead_band_scenario():
    # dead band 0.01 deg, 0.1 deg step: a 0.0326 deg peak-to-peak limit cycle uncompensated
    db = {"alpha": 0.01 * DEG}
    m = run([db, {**db, "fb_motor": 1.0}, {**db, "fb_motor": 0.8}])
    p2p, iae = m[:, MET["p2p_pos"]] / DEG, m[:, MET["iae_pos"]]
    assert p2p[0] == pytest.approx(0.0326, abs=5e-4)
    assert p2p[1] <= 0.0163
    assert iae[2] <= 0.75 * iae[0]
    for b in (1.0, 0.8):
        mm = margins(resolve({**db, "fb_motor": b}), "position")
        assert mm.gm_db >= 6 and mm.pm_deg >= 45


def test_friction_compensation_lowers_iae_with_true_and_wrong_estimates():
    fr = {"friction": 1, "sigma2": 0.1}
    rows = [fr] + [{**fr, "ff_fc": 0.02 * k, "ff_fs": 0.03 * k, "ff_sigma2": 0.1 * k}
                   for k in (1.0, 0.8, 1.2)]
    m = run(rows, duration=2.0)
    iae = m[:, MET["iae_pos"]]
    assert np.all(iae[1:] <= 0.75 * iae[0])
    assert m[1, MET["overshoot"]] < m[0, MET["overshoot"]]


def test_lugre_observer_cancels_the_friction_on_the_paper_scenario():
    # LuGre friction (sigma2 0.1), 0.1 deg step: 11.6 % overshoot, not settled in 2 s without
    # compensation; the observer on the measured motor speed with the true parameters cancels
    # the friction up to the current loop's lag: 2 % settling 0.233 s (frictionless: 0.227 s)
    fr = {"friction": 1, "sigma2": 0.1}
    true = {"ff_fc": 0.02, "ff_fs": 0.03, "ff_sigma2": 0.1, "ff_sigma0": 20.0,
            "ff_sigma1": resolve(fr)["sigma1"]}
    rows = [fr, {**fr, **true}, {}] + [{**fr, **{k: v * f for k, v in true.items()}}
                                       for f in (0.8, 1.2)]
    m = run(rows, duration=2.0)
    settle, iae = m[:, MET["settling_time"]], m[:, MET["iae_pos"]]
    assert math.isnan(settle[0]) or settle[0] > 1.9  # uncompensated: not settled
    assert settle[1] <= 0.35
    assert settle[1] == pytest.approx(settle[2], abs=0.02)  # as if there were no friction
    assert iae[1] == pytest.approx(iae[2], rel=0.05)
    assert np.all(iae[3:] <= 0.75 * iae[0])  # every estimate 20 % off: IAE >= 25 % lower
    # the viscous estimate (a voltage R/Kt*sigma2*w_m, so up to the current loop's lag) takes
    # back the damping sigma2 adds: nearly the frictionless actuator's margins (9.98 dB, 81.9 deg)
    bare = margins(resolve({}), "position")
    comp = margins(resolve({**fr, **true}), "position")
    assert comp.gm_db == pytest.approx(bare.gm_db, abs=0.3) and comp.gm_db >= 6
    assert comp.pm_deg == pytest.approx(bare.pm_deg, abs=5.0) and comp.pm_deg >= 45


def test_lugre_observer_needs_a_coulomb_estimate():
    with pytest.raises(EmaError, match="ff_sigma0"):
        resolve({"ff_sigma0": 20.0})


def test_config_section_sets_the_compensator_parameters():
    cfg = load_config({"controller": {"deadzone_inverse_v": 0.9, "friction_ff_sigma2": 0.1,
                                      "notch_hz": 36.0, "notch_depth_db": -20.0}}, [],
                      StudyConfig)
    p = resolve_run(cfg).params
    assert p["dzi_v"] == 0.9 and p["ff_sigma2"] == 0.1 and p["notch_hz"] == 36.0
    assert p["notch_depth"] == pytest.approx(0.1)
    with pytest.raises(EmaError, match="controller.notch_hz and plant.notch_hz"):
        load_config({"controller": {"notch_hz": 36.0}, "plant": {"notch_hz": 30.0}}, [],
                    StudyConfig)
    with pytest.raises(EmaError, match="notch_depth"):
        resolve({"notch_hz": 30.0, "notch_depth": 1.5})

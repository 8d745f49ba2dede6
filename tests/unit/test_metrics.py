"""The kernel's online metrics against a plain numpy computation on full-resolution signals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ema_cli.model.params import resolve
from ema_cli.sim.signals import InputSignal
from ema_cli.sim.tables import MET, SIG
from ema_cli.units import DEG
from tests.helpers.batch import run_rows


def oracle(t, ref, y, e, ev, cur, u, wl, T, step, t0):
    """Metric definitions written independently with numpy (trapezoid integrals)."""
    dur = t[-1]
    n = len(t) - 1
    out = {
        "iae_pos": np.trapezoid(np.abs(e), t), "ise_pos": np.trapezoid(e**2, t),
        "itae_pos": np.trapezoid(t * np.abs(e), t), "max_pos": np.max(np.abs(e)),
        "iae_vel": np.trapezoid(np.abs(ev), t), "ise_vel": np.trapezoid(ev**2, t),
        "itae_vel": np.trapezoid(t * np.abs(ev), t), "max_vel": np.max(np.abs(ev)),
        "peak_current": np.max(np.abs(cur)), "peak_voltage": np.max(np.abs(u)),
        "peak_load_rate": np.max(np.abs(wl)), "peak_torque": np.max(np.abs(T)),
    }
    out["rms_pos"] = math.sqrt(out["ise_pos"] / dur)
    out["rms_vel"] = math.sqrt(out["ise_vel"] / dur)
    last10 = np.arange(n + 1) >= math.ceil(0.9 * n - 1e-9)
    last20 = np.arange(n + 1) >= math.ceil(0.8 * n - 1e-9)
    out["ss_err_pos"] = np.mean(e[last10])
    out["p2p_pos"] = np.ptp(e[last20])
    out["p2p_vel"] = np.ptp(ev[last20])
    s = y / step
    after = t >= t0
    out["overshoot"] = max(0.0, s[after].max() - 1) * 100
    out["step_peak"] = s[after].max()
    first = lambda lvl: t[after][np.argmax(s[after] >= lvl)]  # noqa: E731
    out["rise_time"] = first(0.9) - first(0.1)
    out["t50"] = first(0.5) - t0
    outside = np.nonzero(after & (np.abs(s - 1) > 0.02))[0]
    out["settling_time"] = t[outside[-1] + 1] - t0 if outside[-1] < n else math.nan
    return out


@pytest.mark.parametrize("over", [{}, {"alpha": 0.05 * DEG}, {"friction": 1, "sigma2": 0.01}])
def test_online_metrics_equal_numpy_on_full_resolution(over):
    step, t0 = 0.1 * DEG, 0.0
    res = run_rows([resolve(over)], InputSignal("step", step, start=t0), duration=0.5,
                   dt=1e-5, output_interval=1e-5)
    s = res.signals[0]
    ref = oracle(res.t_out, s[:, SIG["theta_ref"]], s[:, SIG["theta_load"]],
                 s[:, SIG["err_pos"]], s[:, SIG["err_vel"]], s[:, SIG["current"]],
                 s[:, SIG["voltage_cmd"]], s[:, SIG["omega_load"]], s[:, SIG["torque_shaft"]],
                 step, t0)
    for name, value in ref.items():
        # same samples, same rule: agreement to rounding (summation order differs)
        assert res.metrics[0, MET[name]] == pytest.approx(value, rel=1e-9, abs=1e-15,
                                                          nan_ok=True), name


def test_step_metrics_are_nan_for_non_step_inputs():
    res = run_rows([resolve({})], InputSignal("sine", 1 * DEG, freq=2.0), duration=0.2)
    for name in ("overshoot", "rise_time", "settling_time", "t50", "step_peak"):
        assert math.isnan(res.metrics[0, MET[name]])
    assert res.metrics[0, MET["iae_pos"]] > 0


@pytest.mark.parametrize(("over", "step", "low", "high"), [
    ({"friction": 1}, -0.002 * DEG, 0.05, 0.5), ({"friction": 1}, 0.0005 * DEG, 0.05, 0.5),
    ({}, 20 * DEG, 1.01, 1.1)])
def test_step_peak_is_the_largest_share_of_the_step_reached(over, step, low, high):
    # below the friction threshold the load reaches a small share of the step within 0.1 s
    # (the threshold test's question); a 20 deg step overshoots (3.8 %): step_peak is
    # max(theta_L/step) over every step, not clipped like the overshoot, signed steps alike
    res = run_rows([resolve(over)], InputSignal("step", step), duration=0.1 if over else 0.3,
                   dt=1e-5, output_interval=1e-5)
    share = res.signals[0][:, SIG["theta_load"]] / step
    assert res.metrics[0, MET["step_peak"]] == np.max(share)  # the same samples: exact
    assert low < np.max(share) < high


def test_edge_units_in_metrics_frame():
    res = run_rows([resolve({})], InputSignal("step", 0.1 * DEG), duration=0.2)
    df = res.metrics_frame()
    # max |e| of a 0.1 deg step is the step itself at t = 0, reported in degrees
    assert df["max_abs_err_pos_deg"][0] == pytest.approx(0.1, rel=1e-12)
    assert not df["diverged"][0]

"""Convergence in dt, batch = single runs bit for bit, determinism, divergence isolation."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli.model.params import INDEX, resolve, to_row
from ema_cli.sim.signals import InputSignal
from ema_cli.units import DEG
from tests.helpers.batch import LINEAR_OVERRIDES, run_rows


def _theta_at_common_times(p, signal, duration, dts, out_dt):
    return [run_rows([p], signal, duration, dt, out_dt).signals[0, :, 1] for dt in dts]


def test_rk4_order_about_four_on_smooth_case():
    # Linear loop, smooth (sine) input. Errors against a dt/16 reference fit a slope of ~4
    # on log(err) vs log(dt) (np.polyfit); accepted 3.7..4.3.
    p = resolve(LINEAR_OVERRIDES)
    sig = InputSignal("sine", 2.0 * DEG, freq=5.0)
    dts = [1.6e-4, 8e-5, 4e-5, 2e-5]
    runs = _theta_at_common_times(p, sig, 0.08, dts + [1e-5 / 2], 1.6e-4)
    ref = runs[-1]
    errs = [np.max(np.abs(r - ref)) for r in runs[:-1]]
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert 3.7 <= slope <= 4.3, (slope, errs)


def _rms_errors(p, sig, dts, duration=0.2, out_dt=4e-5):
    runs = _theta_at_common_times(p, sig, duration, dts, out_dt)
    return [float(np.sqrt(np.mean((r - runs[-1]) ** 2))) for r in runs[:-1]]


def test_nonlinear_case_converges_as_dt_halves():
    # Backlash (paper Eq. 2: torque continuous across the gap), LuGre friction and an
    # amplifier dead zone, 20 deg step, saturations removed: the RMS error against a
    # dt = 3.125e-7 s reference falls at every halving, at first order (the kinks and the held
    # bristle torque are resolved to the step): fitted slope 0.9..1.3.
    p = resolve({"alpha": 0.01 * DEG, "damping": "paper", "friction": 1, "sigma2": 0.001,
                 "d1": 0.01, "sat1": "off", "sat2": "off", "sat3": "off"})
    dts = [2e-5, 1e-5, 5e-6, 2.5e-6, 1.25e-6, 3.125e-7]
    errs = _rms_errors(p, InputSignal("step", 20.0 * DEG), dts)
    assert all(b < a for a, b in zip(errs, errs[1:], strict=False)), errs
    assert 0.9 <= np.polyfit(np.log(dts[:-1]), np.log(errs), 1)[0] <= 1.3, errs


@pytest.mark.parametrize("label,over", [
    ("contact impacts", {"alpha": 0.01 * DEG, "friction": 1, "sigma2": 0.001,
                         "sat1": "off", "sat2": "off", "sat3": "off"}),
    ("default saturations", {"alpha": 0.01 * DEG, "friction": 1, "sigma2": 0.001}),
])
def test_switched_cases_converge_to_within_1e5_of_the_step(label, over):
    # Contact-form impacts make the torque jump, and the voltage limit's clamping anti-windup
    # slides along |u| = 40 V: a fixed step resolves both to O(dt) with an irregular constant,
    # so the error is not monotone in dt; it is small at the default dt and shrinks overall.
    step = 20.0 * DEG
    dts = [4e-5, 1e-5, 2.5e-6, 6.25e-7]
    errs = _rms_errors(resolve(over), InputSignal("step", step), dts)
    assert errs[1] < 1e-5 * step, (label, errs)  # default dt: RMS error < 1e-5 of the step
    assert errs[-1] < errs[0] / 4, (label, errs)


def test_batch_equals_single_runs_bit_for_bit_and_runs_repeat():
    rows = [
        resolve({}),
        resolve({"alpha": 0.01 * DEG}),
        resolve({"friction": 1, "sigma2": 0.01}),
        resolve({"d1": 0.1, "d3": 0.5, "d4": 0.001 * DEG}),
        resolve({"sat1": "off", "sat2": "off", "sat3": "off"}),
    ]
    sig = InputSignal("step", 20.0 * DEG)
    batch = run_rows(rows, sig, 0.1, 1e-5, 1e-4)
    again = run_rows(rows, sig, 0.1, 1e-5, 1e-4)
    parallel = run_rows(rows, sig, 0.1, 1e-5, 1e-4, parallel=True)
    for k, r in enumerate(rows):
        single = run_rows([r], sig, 0.1, 1e-5, 1e-4)
        assert np.array_equal(single.metrics[0], batch.metrics[k], equal_nan=True)
        assert np.array_equal(single.signals[0], batch.signals[k], equal_nan=True)
    assert np.array_equal(batch.metrics, again.metrics, equal_nan=True)
    assert np.array_equal(batch.signals, again.signals, equal_nan=True)
    assert np.array_equal(batch.metrics, parallel.metrics, equal_nan=True)
    assert np.array_equal(batch.signals, parallel.signals, equal_nan=True)


def test_diverging_row_is_flagged_and_neighbours_unaffected():
    good = np.array(to_row(resolve({})))
    bad = good.copy()
    bad[INDEX["bL"]] = -50.0  # negative load damping: the load runs away exponentially
    sig = InputSignal("step", 20.0 * DEG)
    mixed = run_rows([good, bad, good], sig, 0.5, 1e-5, 1e-3)
    alone = run_rows([good], sig, 0.5, 1e-5, 1e-3)
    assert list(mixed.diverged) == [False, True, False]
    assert np.array_equal(mixed.metrics[0], alone.metrics[0], equal_nan=True)
    assert np.array_equal(mixed.metrics[2], alone.metrics[0], equal_nan=True)
    assert np.array_equal(mixed.signals[2], alone.signals[0], equal_nan=True)
    t_end = mixed.metrics_frame()["t_end_s"][1]
    assert 0 < t_end < 0.5
    assert np.isnan(mixed.signals[1, -1, 1])  # samples after divergence are NaN

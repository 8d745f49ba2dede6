"""The slow-triangle acceptance tests, each batched over units (one kernel batch per memory
block): the hysteresis (a triangle command; loop width and free play) and the locked-motor load
deflection (a load-torque triangle; stiffness and free play)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ema_cli.acceptance.battery import (
    BRANCH_MARGIN,
    FIT_RMS_SHARE,
    FOLLOW_SHARE,
    RECORD_PER_PERIOD,
    REVERSAL_SHARE,
    _bound,
    _interval,
    _m,
    _simulate,
    _whole,
)
from ema_cli.acceptance.measurement import TestRun
from ema_cli.config.acceptance import HysteresisTest, LoadDeflectionTest
from ema_cli.errors import EmaError
from ema_cli.units import DEG


def triangle(amplitude: float, period: float, cycles: int) -> tuple[tuple[float, ...],
                                                                      tuple[float, ...]]:
    """Vertices of 0 -> +A -> -A -> 0 per period, ``cycles`` periods -> (t [s], value)."""
    t = [0.0] + [period / 4 + k * period / 2 for k in range(2 * cycles)] + [cycles * period]
    y = [0.0] + [amplitude if k % 2 == 0 else -amplitude for k in range(2 * cycles)] + [0.0]
    return tuple(t), tuple(y)


CLOSURE_SHARE = 0.02  # the load's gap between the measured period's ends, at most, in widths [-]


def peak_triangle(amplitude: float, period: float, cycles: int) -> tuple[tuple[float, ...],
                                                                           tuple[float, ...]]:
    """Vertices of the hysteresis command: 0 -> +A in a quarter period, then ``cycles``
    periods +A -> -A -> +A -> (t [s], value)."""
    t = [0.0] + [period / 4 + k * period / 2 for k in range(2 * cycles + 1)]
    y = [0.0] + [amplitude if k % 2 == 0 else -amplitude for k in range(2 * cycles + 1)]
    return tuple(t), tuple(y)


def _last_period(period: float, cycles: int) -> float:
    """When the measured (last) period of :func:`peak_triangle` starts, at a +A vertex [s]."""
    return period / 4 + (cycles - 1) * period


def _branches(t: np.ndarray, period: float, cycles: int) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the rising and falling command in the last period of :func:`peak_triangle`
    (vertex instants out)."""
    tau = t - _last_period(period, cycles)
    last = (tau > 0) & (tau < period)
    return last & (tau > period / 2), last & (tau < period / 2)


def _at_same(x_a: np.ndarray, y_a: np.ndarray, x_b: np.ndarray, y_b: np.ndarray,
             grid: np.ndarray) -> np.ndarray:
    """``y_a(grid) - y_b(grid)``, each branch interpolated on its own ``x`` (sorted)."""
    ia, ib = np.argsort(x_a), np.argsort(x_b)
    return np.interp(grid, x_a[ia], y_a[ia]) - np.interp(grid, x_b[ib], y_b[ib])


def run_hysteresis(name: str, test: HysteresisTest, units: Sequence[Mapping[str, float]],
                   dt: float) -> list[TestRun]:
    from ema_cli.sim.signals import InputSignal

    A = test.amplitude_deg * DEG
    P = _whole(test.period_s, dt)
    table = peak_triangle(A, P, test.cycles)
    duration = table[0][-1]  # the last vertex
    sig = InputSignal(kind="csv", table=table, path="triangle")
    return [_hysteresis_case(name, test, res, k, P)
            for _, res in _simulate(units, [sig], dt, duration,
                                    _interval(P, dt, RECORD_PER_PERIOD))
            for k in range(len(res.P))]


def _hysteresis_case(name: str, test: HysteresisTest, res: Any, case: int,
                     P: float) -> TestRun:
    A = test.amplitude_deg * DEG
    t = res.t_out
    c, y, xm = (res.signal(n, case) for n in ("theta_ref", "theta_load", "theta_motor"))
    up, down = _branches(t, P, test.cycles)
    grid = np.linspace(-BRANCH_MARGIN * A, BRANCH_MARGIN * A, 401)
    width = float(np.max(np.abs(_at_same(c[down], y[down], c[up], y[up], grid))))
    y_lo = max(np.min(y[up]), np.min(y[down]))
    y_hi = min(np.max(y[up]), np.max(y[down]))
    ygrid = np.linspace(y_lo + (1 - BRANCH_MARGIN) * (y_hi - y_lo) / 2,
                        y_hi - (1 - BRANCH_MARGIN) * (y_hi - y_lo) / 2, 401)
    play = float(np.median(_at_same(y[up], xm[up], y[down], xm[down], ygrid)))
    cond = f"{test.amplitude_deg:g} deg, {4 * test.amplitude_deg / P:.3g} deg/s"
    notes = ["diverged"] if res.diverged[case] else []
    t0 = _last_period(P, test.cycles)  # the measured period's ends: the command at +A
    gap = abs(float(np.interp(t0 + P, t, y) - np.interp(t0, t, y)))
    if width > 0 and gap > CLOSURE_SHARE * width:
        notes.append(f"the loop does not close: the load angle at the measured period's end "
                     f"differs from its start by {gap / DEG:.3g} deg, {100 * gap / width:.0f} % "
                     "of the width (a transient or a limit cycle: the width depends on the "
                     "window); raise cycles")
    reversing = _reversals(y, c, up, A) + _reversals(-y, c, down, A)
    span = y_hi - y_lo
    if not span >= FOLLOW_SHARE * 2 * A:
        why = (f"the load moved {span / DEG:.3g} deg on the last period, less than "
               f"{100 * FOLLOW_SHARE:g} % of the command's {2 * test.amplitude_deg:g} deg: no "
               "loop to read; raise amplitude_deg")
        out = [_bound("hysteresis", "hysteresis", cond, 0.0, math.inf, why),
               _bound("hysteresis", "free_play", cond, 0.0, math.inf, why)]
    elif reversing > REVERSAL_SHARE:
        why = (f"the load reverses on {100 * reversing:.0f} % of the branches (a limit cycle): "
               "the free play is not read reliably; close the loop on the motor angle for "
               "this test (set: {controller.position_feedback: motor})")
        notes.append(why)
        out = [_m("hysteresis", "hysteresis", cond, width),
               _bound("hysteresis", "free_play", cond, 0.0, math.inf, why)]
    else:
        out = [_m("hysteresis", "hysteresis", cond, width),
               _m("hysteresis", "free_play", cond, abs(play))]
    return TestRun(name, "hysteresis", out, {"t": t, "ref": c, "load": y, "motor": xm,
                                             "rising": up, "falling": down}, notes=notes)


def _reversals(y: np.ndarray, c: np.ndarray, branch: np.ndarray, A: float) -> float:
    """The share of a branch's interior samples (``|command| <= BRANCH_MARGIN*A``) where the
    load moves against the branch (``y`` decreasing on a rising branch) [-], halved."""
    inner = branch[1:] & branch[:-1] & (np.abs(c[1:]) <= BRANCH_MARGIN * A)
    if not inner.any():
        return 0.0
    return 0.5 * float(np.mean(np.diff(y)[inner] < 0))


def run_load_deflection(name: str, test: LoadDeflectionTest,
                        units: Sequence[Mapping[str, float]], dt: float) -> list[TestRun]:
    from ema_cli.sim.signals import InputSignal

    P = _whole(test.period_s, dt)
    sig = InputSignal(kind="step", amplitude=0.0, load_table=triangle(test.torque_nm, P, 1))
    return [_deflection_case(name, test, res, k)
            for _, res in _simulate([{**p, "locked": 1.0} for p in units], [sig], dt, P,
                                    _interval(P, dt, RECORD_PER_PERIOD))
            for k in range(len(res.P))]


def _deflection_case(name: str, test: LoadDeflectionTest, res: Any, case: int) -> TestRun:
    tq, y = res.signal("torque_load", case), res.signal("theta_load", case)
    edge = test.fit_fraction * test.torque_nm
    pos, neg = tq >= edge, tq <= -edge
    # theta_L = s*T + b_pos on the positive branch, s*T + b_neg on the negative one
    X = np.column_stack([tq[pos | neg], pos[pos | neg], neg[pos | neg]]).astype(float)
    if not (pos.any() and neg.any()):
        raise EmaError(f"test {name}: no recorded load torque beyond fit_fraction on both "
                       "branches; lengthen period_s")
    (s, b_pos, b_neg), *_ = np.linalg.lstsq(X, y[pos | neg], rcond=None)
    cond = f"+-{test.torque_nm:g} N*m, motor locked"
    fitted = y[pos | neg]
    rms = float(np.sqrt(np.mean((X @ np.array([s, b_pos, b_neg]) - fitted) ** 2)))
    spread = float(np.ptp(fitted)) if len(fitted) else 0.0
    if not (s > 0 and np.isfinite(rms)):
        why = (f"the load angle does not follow the torque along a line (slope {s:.3g} "
               "rad/(N*m)): lengthen period_s (slower than the load's resonance), and check "
               "that the motor is locked and the transmission elastic")
    elif rms > FIT_RMS_SHARE * spread:
        why = (f"the load angle is not one line per branch where |T| >= fit_fraction*T (rms "
               f"residual {100 * rms / spread:.3g} % of its span, over "
               f"{100 * FIT_RMS_SHARE:g} %): raise fit_fraction or lengthen period_s")
    else:
        why = ""
    if why:
        out = [_bound("load_deflection", "stiffness", cond, 0.0, math.inf, why),
               _bound("load_deflection", "free_play", cond, 0.0, math.inf, why)]
    else:
        out = [_m("load_deflection", "stiffness", cond, 1.0 / s),
               _m("load_deflection", "free_play", cond, b_pos - b_neg)]
    return TestRun(name, "load_deflection", out,
                   {"torque": tq, "load": y, "slope": s, "b_pos": b_pos, "b_neg": b_neg,
                    "fit_from": test.fit_fraction * test.torque_nm},
                   notes=["diverged"] if res.diverged[case] else [])

"""The actuator acceptance battery: one function per test kind, each returning measurements.

Every test runs on the SI parameters of the actuator under test (``params``) with the
simulator's step ``dt`` [s] and returns a :class:`TestRun`: measurements in SI (one per metric
and condition, e.g. per amplitude or per loop), the data its figure needs, notes. The limits
are compared in :func:`verdicts`. What each test does (docs/model.md, "Acceptance battery"):

* ``step``: a reference step; the kernel's 10-90 % rise time, overshoot, 2 % settling time,
  steady-state error (mean over the last 10 % of the run) and peak current.
* ``frequency_response``: a sinestream (:func:`analysis.freqresp.sinestream`) at each
  amplitude: -3 dB bandwidth, phase lag at ``phase_at_hz`` (that frequency is simulated), peak
  gain.
* ``margins``: gain and phase margins of the linear limit, each loop broken in turn.
* ``threshold``: the smallest step the load follows to ``fraction`` of its size within
  ``within_s``: a batched k-section search (8 amplitudes per kernel call, log-spaced) down to a
  relative resolution ``rtol``; the result is the smallest amplitude that passed with every
  larger amplitude tried passing too.
* ``hysteresis``: a slow triangle command 0 -> +A -> -A -> 0 per period; on the last period,
  the loop width (the largest difference of the load angle between the falling and the rising
  branch at the same command) and the free play (the median difference of the motor angle / m
  between the rising and the falling branch at the same load angle).
* ``load_deflection``: motor locked, a load-torque triangle 0 -> +T -> -T -> 0; the load angle
  against the torque where ``|T| >= fit_fraction * T``, fitted by one slope and two intercepts:
  stiffness = 1 / slope, free play = the gap between the intercepts (the loading and
  unloading halves of each branch cancel the damping lag).
* ``dynamic_stiffness``: a sine load torque in closed loop; ``|T / theta_L|`` over frequency,
  its minimum refined around the grid's minimum by two rounds of 8 frequencies.
* ``no_load_rate``: the peak load rate on a large step.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ema_cli.acceptance.measurement import Measurement, TestRun
from ema_cli.config.acceptance import (
    METRICS,
    DynamicStiffnessTest,
    FrequencyResponseTest,
    HysteresisTest,
    LoadDeflectionTest,
    MarginsTest,
    NoLoadRateTest,
    StepTest,
    ThresholdTest,
)
from ema_cli.errors import EmaError
from ema_cli.sim.tables import MET, SIG
from ema_cli.units import DEG, SI_UNIT

RECORD_PER_PERIOD = 4000  # recorded samples per period of the slow triangle tests [-]
STEP_RECORD_S = 1e-4  # recording interval of step tests [s]
THRESHOLD_BATCH = 8  # amplitudes per kernel call in the threshold search [-]
THRESHOLD_ROUNDS = 12  # k-section rounds at most [-]
BRANCH_MARGIN = 0.8  # loop widths are read where |command| <= this share of A [-]
REVERSAL_SHARE = 0.02  # load moving against its branch this often: a limit cycle [-]
REFINE_ROUNDS, REFINE_POINTS = 2, 8  # dynamic-stiffness refinement around the minimum [-]
PEAK_DC_DB = 0.5  # a peak gain at the lowest frequency above this is not the loop's DC level [dB]
FOLLOW_SHARE = 0.5  # the hysteresis reads a loop when the load spans this share of 2A [-]
FIT_RMS_SHARE = 0.02  # load deflection: the two-line fit's rms residual, at most, per span [-]


def _m(kind: str, metric: str, condition: str, value: float, note: str = "") -> Measurement:
    return Measurement(metric, condition, float(value), SI_UNIT[METRICS[kind][metric]], note)


def _bound(kind: str, metric: str, condition: str, lower: float, upper: float, reason: str,
           note: str = "") -> Measurement:
    """A value known only to lie in ``[lower, upper]`` (SI): not measured, for ``reason``."""
    edge = lower if math.isfinite(lower) and lower > 0 else upper
    if not math.isfinite(edge):
        edge = math.nan
    return Measurement(metric, condition, float(edge), SI_UNIT[METRICS[kind][metric]], note,
                       float(lower), float(upper), reason)


def _simulate(params: Mapping[str, float], signals: list[Any], dt: float, duration: float,
              interval: float | None, rows: list[Mapping[str, float]] | None = None) -> Any:
    """One kernel batch: every signal with ``params`` (or each of ``rows``)."""
    from ema_cli.model.params import to_row
    from ema_cli.sim.grid import plan_steps
    from ema_cli.sim.runner import simulate_batch

    n_steps, dec = plan_steps(duration, dt, interval)
    rows = rows or [params] * len(signals)
    P = np.array([to_row(r) for r in rows])
    return simulate_batch(P, signals, np.arange(len(signals)), dt, n_steps, dec,
                          parallel=len(signals) > 1)


def _whole(duration: float, dt: float) -> float:
    """``duration`` rounded up to a whole number of steps ``dt`` [s]."""
    return math.ceil(duration / dt - 1e-9) * dt


def _interval(duration: float, dt: float, samples: int) -> float:
    """A recording interval, a whole number of steps, giving about ``samples`` samples."""
    return max(1, round(duration / samples / dt)) * dt


# ------------------------------------------------------------------------------- the tests
def run_step(name: str, test: StepTest, params: Mapping[str, float], dt: float) -> TestRun:
    from ema_cli.sim.signals import InputSignal

    duration = _whole(test.duration_s, dt)
    res = _simulate(params, [InputSignal(kind="step", amplitude=test.amplitude_deg * DEG)], dt,
                    duration, _interval(duration, dt, 10000))
    met = res.metrics[0]
    cond = f"{test.amplitude_deg:g} deg"
    settle, rise = met[MET["settling_time"]], met[MET["rise_time"]]
    notes = ["diverged"] if res.diverged[0] else []
    out = []
    if res.diverged[0] or math.isfinite(settle):
        # settled within the run (or diverged: NaN values, judged INCONCLUSIVE)
        out += [_m("step", "rise_time", cond, rise),
                _m("step", "overshoot", cond, met[MET["overshoot"]]),
                _m("step", "settling_time", cond, settle),
                _m("step", "steady_state_error", cond, abs(met[MET["ss_err_pos"]])),
                _m("step", "peak_current", cond, met[MET["peak_current"]])]
    else:
        end = f"by the end of the run, {duration:g} s: lengthen duration_s"
        if math.isfinite(rise):
            out.append(_m("step", "rise_time", cond, rise))
        else:
            # 90 % not reached: the rise takes longer than from the 10 % crossing to the end
            share = res.signal("theta_load") / (test.amplitude_deg * DEG)
            k10 = np.flatnonzero(share >= 0.1)
            low = duration - res.t_out[k10[0]] if len(k10) else 0.0
            out.append(_bound("step", "rise_time", cond, low, math.inf,
                              f"the load did not reach 90 % of the step {end}"))
        out += [_bound("step", "overshoot", cond, met[MET["overshoot"]], math.inf,
                       f"the load had not settled {end} (the overshoot may still grow)"),
                _bound("step", "settling_time", cond, duration, math.inf,
                       f"not settled within 2 % {end}"),
                _bound("step", "steady_state_error", cond, 0.0, math.inf,
                       f"no steady state: the load had not settled {end}"),
                _bound("step", "peak_current", cond, met[MET["peak_current"]], math.inf,
                       f"the load had not settled {end} (the current may still peak)")]
    return TestRun(name, "step", out, {"t": res.t_out, "ref": res.signal("theta_ref"),
                                       "load": res.signal("theta_load"),
                                       "amplitude_deg": test.amplitude_deg}, notes=notes)


def run_frequency_response(name: str, test: FrequencyResponseTest, params: Mapping[str, float],
                           dt: float) -> TestRun:
    from ema_cli.analysis.freqresp import binding_limit, crossing, sinestream, snap_frequency
    from ema_cli.analysis.linear import linear_model

    freqs = list(np.geomspace(test.f_min_hz, test.f_max_hz, test.n))
    if test.phase_at_hz is not None:
        freqs = sorted({*freqs, test.phase_at_hz})
    amps = list(test.amplitudes_deg)
    points = sinestream(params, amps, freqs, dt=dt)
    nf = len(freqs)
    out: list[Measurement] = []
    notes = []
    f_at = snap_frequency(test.phase_at_hz, dt)[0] if test.phase_at_hz is not None else None
    for k, a in enumerate(amps):
        blk = points[k * nf:(k + 1) * nf]
        f = np.array([p.f_hz for p in blk])
        g = np.array([p.gain_db for p in blk])
        cond = f"{a:g} deg"
        bw = crossing(f, g, -3.0)
        lim = binding_limit(blk, bw if math.isfinite(bw) else math.nan)
        note = f"binding limit {lim}" if lim is not None else ""
        if math.isfinite(bw):
            out.append(_m("frequency_response", "bandwidth", cond, bw, note))
        elif np.all(g > -3.0):
            out.append(_bound("frequency_response", "bandwidth", cond, f[-1], math.inf,
                              f"bandwidth above the highest frequency measured, {f[-1]:.3g} "
                              "Hz: widen f_max_hz", note))
        else:
            out.append(_bound("frequency_response", "bandwidth", cond, 0.0, f[0],
                              f"bandwidth below the lowest frequency measured, {f[0]:.3g} Hz: "
                              "lower f_min_hz", note))
        if f_at is not None:
            j = int(np.argmin(np.abs(f - f_at)))
            out.append(_m("frequency_response", "phase_lag", f"{cond} at {f_at:.4g} Hz",
                          -blk[j].phase_deg * DEG))
        k = int(np.argmax(g))
        if k == len(g) - 1 and len(g) > 1:
            out.append(_bound("frequency_response", "peak_gain", cond, float(g[k]), math.inf,
                              f"the gain is highest at the highest frequency measured, "
                              f"{f[k]:.4g} Hz (it may rise further): widen f_max_hz"))
        elif k == 0 and g[0] > PEAK_DC_DB:
            out.append(_bound("frequency_response", "peak_gain", cond, float(g[k]), math.inf,
                              f"the gain is highest, {g[0]:.3g} dB, at the lowest frequency "
                              f"measured, {f[0]:.4g} Hz (it may rise below): lower f_min_hz"))
        else:
            out.append(_m("frequency_response", "peak_gain", cond, float(g[k]),
                          f"at {f[k]:.4g} Hz"))
        if any(p.diverged for p in blk):
            notes.append(f"{cond}: diverged at some frequency")
    fs = np.array([p.f_hz for p in points[:nf]])
    return TestRun(name, "frequency_response", out,
                   {"points": points, "amplitudes": amps, "f_hz": fs,
                    "linear": linear_model(params).response(fs)}, notes=notes)


def run_margins(name: str, test: MarginsTest, params: Mapping[str, float], dt: float) -> TestRun:
    from ema_cli.analysis.linear import loop_transfer, margins
    from ema_cli.config.acceptance import MARGINS_F_MIN_HZ

    out = []
    loops = {}
    res = {}
    f = np.geomspace(0.1, 1e4, 2000)
    f_top = test.f_max_hz
    for loop in test.loops:
        m = margins(params, loop, f_min=MARGINS_F_MIN_HZ, f_max=f_top)
        res[loop] = m
        loops[loop] = loop_transfer(params, loop, f)
        L_top, L_below, L_bottom = (abs(complex(x)) for x in loop_transfer(
            params, loop, np.array([f_top, f_top / 1.01, MARGINS_F_MIN_HZ])))
        # above f_top, |L| is taken to keep falling if it falls at f_top (strictly proper)
        falls = L_top < 1.0 and L_top < L_below
        top = (f"up to f_max_hz = {f_top:g} Hz (|L| = {20 * math.log10(L_top):.3g} dB there"
               f"{'' if falls else ', not falling'}): widen f_max_hz")
        cond = f"{loop} loop"
        if math.isfinite(m.f_gm_hz):
            out.append(_m("margins", "gain_margin", cond, m.gm_db, f"at {m.f_gm_hz:.4g} Hz"))
        else:
            # no phase crossover up to f_top: one above it has |L| < |L(f_top)|
            low = -20.0 * math.log10(L_top) if falls else -math.inf
            out.append(_bound("margins", "gain_margin", cond, low, math.inf,
                              f"no phase crossover {top}", "no phase crossover"))
        if math.isfinite(m.f_pm_hz):
            out.append(_m("margins", "phase_margin", cond, m.pm_deg * DEG,
                          f"at {m.f_pm_hz:.4g} Hz"))
        elif falls and L_bottom < 1.0:
            out.append(_m("margins", "phase_margin", cond, math.inf,
                          f"no gain crossover: |L| < 1 from {MARGINS_F_MIN_HZ:g} Hz up"))
        else:
            out.append(_bound("margins", "phase_margin", cond, -math.pi, math.pi,
                              f"no gain crossover {top}"))
    return TestRun(name, "margins", out, {"f_hz": f, "loops": loops, "margins": res},
                   notes=["linear limit: saturations, dead zones and backlash removed, friction "
                          "viscous, controller continuous"])


def step_fractions(params: Mapping[str, float], amplitudes: np.ndarray, within_s: float,
                   dt: float) -> np.ndarray:
    """The largest share of each step ``amplitudes`` [rad] the load reaches within
    ``within_s`` [s] (one kernel batch)."""
    from ema_cli.sim.signals import InputSignal

    duration = _whole(within_s, dt)
    sigs = [InputSignal(kind="step", amplitude=float(a)) for a in amplitudes]
    res = _simulate(params, sigs, dt, duration, dt)
    y = res.signals[:, :, SIG["theta_load"]]
    return np.max(y * np.sign(amplitudes)[:, None], axis=1) / np.abs(amplitudes)


def run_threshold(name: str, test: ThresholdTest, params: Mapping[str, float],
                  dt: float) -> TestRun:
    lo, hi = (v * DEG for v in test.search_deg)
    tried: dict[float, float] = {}

    def evaluate(amps: np.ndarray) -> None:
        for a, frac in zip(amps, step_fractions(params, amps, test.within_s, dt), strict=True):
            tried[float(a)] = float(frac)

    evaluate(np.geomspace(lo, hi, THRESHOLD_BATCH))
    for _ in range(THRESHOLD_ROUNDS):
        amps = sorted(tried)
        ok = [tried[a] >= test.fraction for a in amps]
        if all(ok):
            break
        last_fail = max(k for k, v in enumerate(ok) if not v)
        if last_fail == len(amps) - 1:
            break
        a_f, a_p = amps[last_fail], amps[last_fail + 1]
        if a_p / a_f - 1.0 <= test.rtol:
            break
        evaluate(np.geomspace(a_f, a_p, THRESHOLD_BATCH + 2)[1:-1])
    amps = sorted(tried)
    ok = [tried[a] >= test.fraction for a in amps]
    cond = f"{100 * test.fraction:g} % within {test.within_s:g} s"
    if all(ok):
        value = amps[0]
        m = _bound("threshold", "threshold", cond, 0.0, value,
                   f"followed at every step down to the search minimum {lo / DEG:g} deg: "
                   "lower search_deg")
    elif not ok[-1]:
        value = math.inf
        m = _bound("threshold", "threshold", cond, hi, math.inf,
                   f"not followed even at the search maximum {hi / DEG:g} deg: raise "
                   "search_deg")
    else:
        last_fail = max(k for k, v in enumerate(ok) if not v)
        value = amps[last_fail + 1]
        m = _m("threshold", "threshold", cond, value,
               f"between {amps[last_fail] / DEG:.4g} and {value / DEG:.4g} deg")
    return TestRun(name, "threshold", [m],
                   {"tried": tried, "fraction": test.fraction, "value": value})


def triangle(amplitude: float, period: float, cycles: int) -> tuple[tuple[float, ...],
                                                                      tuple[float, ...]]:
    """Vertices of 0 -> +A -> -A -> 0 per period, ``cycles`` periods -> (t [s], value)."""
    t = [0.0] + [period / 4 + k * period / 2 for k in range(2 * cycles)] + [cycles * period]
    y = [0.0] + [amplitude if k % 2 == 0 else -amplitude for k in range(2 * cycles)] + [0.0]
    return tuple(t), tuple(y)


def _branches(t: np.ndarray, period: float, cycles: int) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the rising and falling command in the last period (vertex instants out)."""
    tau = t - (cycles - 1) * period
    last = (tau > 0) & (tau < period)
    falling = last & (tau > period / 4) & (tau < 3 * period / 4)
    rising = last & ((tau < period / 4) | (tau > 3 * period / 4))
    return rising, falling


def _at_same(x_a: np.ndarray, y_a: np.ndarray, x_b: np.ndarray, y_b: np.ndarray,
             grid: np.ndarray) -> np.ndarray:
    """``y_a(grid) - y_b(grid)``, each branch interpolated on its own ``x`` (sorted)."""
    ia, ib = np.argsort(x_a), np.argsort(x_b)
    return np.interp(grid, x_a[ia], y_a[ia]) - np.interp(grid, x_b[ib], y_b[ib])


def run_hysteresis(name: str, test: HysteresisTest, params: Mapping[str, float],
                   dt: float) -> TestRun:
    from ema_cli.sim.signals import InputSignal

    A = test.amplitude_deg * DEG
    P = _whole(test.period_s, dt)
    duration = P * test.cycles
    sig = InputSignal(kind="csv", table=triangle(A, P, test.cycles), path="triangle")
    res = _simulate(params, [sig], dt, duration, _interval(P, dt, RECORD_PER_PERIOD))
    t = res.t_out
    c, y, xm = (res.signal(n) for n in ("theta_ref", "theta_load", "theta_motor"))
    up, down = _branches(t, P, test.cycles)
    grid = np.linspace(-BRANCH_MARGIN * A, BRANCH_MARGIN * A, 401)
    width = float(np.max(np.abs(_at_same(c[down], y[down], c[up], y[up], grid))))
    y_lo = max(np.min(y[up]), np.min(y[down]))
    y_hi = min(np.max(y[up]), np.max(y[down]))
    ygrid = np.linspace(y_lo + (1 - BRANCH_MARGIN) * (y_hi - y_lo) / 2,
                        y_hi - (1 - BRANCH_MARGIN) * (y_hi - y_lo) / 2, 401)
    play = float(np.median(_at_same(y[up], xm[up], y[down], xm[down], ygrid)))
    cond = f"{test.amplitude_deg:g} deg, {4 * test.amplitude_deg / P:.3g} deg/s"
    notes = ["diverged"] if res.diverged[0] else []
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


def run_load_deflection(name: str, test: LoadDeflectionTest, params: Mapping[str, float],
                        dt: float) -> TestRun:
    from ema_cli.sim.signals import InputSignal

    P = _whole(test.period_s, dt)
    sig = InputSignal(kind="step", amplitude=0.0, load_table=triangle(test.torque_nm, P, 1))
    res = _simulate({**params, "locked": 1.0}, [sig], dt, P,
                    _interval(P, dt, RECORD_PER_PERIOD))
    tq, y = res.signal("torque_load"), res.signal("theta_load")
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
                   notes=["diverged"] if res.diverged[0] else [])


def run_dynamic_stiffness(name: str, test: DynamicStiffnessTest, params: Mapping[str, float],
                          dt: float) -> TestRun:
    from ema_cli.analysis.freqresp import compliance_stream
    from ema_cli.analysis.linear import linear_model

    freqs = np.geomspace(test.f_min_hz, test.f_max_hz, test.n)
    pts = compliance_stream(params, test.amplitude_nm, freqs, dt)
    for _ in range(REFINE_ROUNDS):
        pts.sort(key=lambda p: p.f_hz)
        k = int(np.argmin([p.stiffness for p in pts]))
        lo = pts[max(k - 1, 0)].f_hz
        hi = pts[min(k + 1, len(pts) - 1)].f_hz
        if hi <= lo:
            break
        more = np.geomspace(lo, hi, REFINE_POINTS + 2)[1:-1]
        pts += compliance_stream(params, test.amplitude_nm, more, dt)
    pts.sort(key=lambda p: p.f_hz)
    k = int(np.argmin([p.stiffness for p in pts]))
    f = np.array([p.f_hz for p in pts])
    cond = f"{test.amplitude_nm:g} N*m, {test.f_min_hz:g}-{test.f_max_hz:g} Hz"
    if k in (0, len(pts) - 1):
        edge, key = (("lowest", "lower f_min_hz") if k == 0 else ("highest", "widen f_max_hz"))
        out = [_bound("dynamic_stiffness", "dynamic_stiffness", cond, 0.0, pts[k].stiffness,
                      f"the minimum lies at the {edge} frequency measured, {pts[k].f_hz:.4g} Hz "
                      f"(it may fall beyond): {key}", f"at {pts[k].f_hz:.4g} Hz")]
    else:
        out = [_m("dynamic_stiffness", "dynamic_stiffness", cond, pts[k].stiffness,
                  f"at {pts[k].f_hz:.4g} Hz")]
    lin = linear_model(params).response(f, inp="torque_disturbance")
    reached = sorted({x for p in pts for x in p.limits})
    return TestRun(name, "dynamic_stiffness", out,
                   {"points": pts, "f_hz": f, "linear": lin, "k_min": k},
                   notes=[f"limits reached: {', '.join(reached)}"] if reached else [])


def run_no_load_rate(name: str, test: NoLoadRateTest, params: Mapping[str, float],
                     dt: float) -> TestRun:
    from ema_cli.sim.signals import InputSignal

    duration = _whole(test.duration_s, dt)
    res = _simulate(params, [InputSignal(kind="step", amplitude=test.amplitude_deg * DEG)], dt,
                    duration, _interval(duration, dt, 10000))
    cond = f"{test.amplitude_deg:g} deg step"
    rate = res.metrics[0, MET["peak_load_rate"]]
    w = np.abs(res.signal("omega_load"))
    if len(w) > 2 and np.all(np.isfinite(w)) and int(np.argmax(w)) >= len(w) - 2:
        m = _bound("no_load_rate", "rate", cond, rate, math.inf,
                   f"the load was still accelerating at the end of the run, {duration:g} s: "
                   "lengthen duration_s")
    else:
        m = _m("no_load_rate", "rate", cond, rate)
    return TestRun(name, "no_load_rate", [m],
                   {"t": res.t_out, "rate": res.signal("omega_load"),
                    "amplitude_deg": test.amplitude_deg},
                   notes=["diverged"] if res.diverged[0] else [])

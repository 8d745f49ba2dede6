"""The actuator acceptance battery: one function per test kind, each returning measurements.

Every test runs on the SI parameters of each actuator under test (``units``: one for
``ema acceptance``, a batch of sampled units for ``ema yield``) with the simulator's step
``dt`` [s], all units in the same kernel batches, and returns one :class:`TestRun` per unit:
measurements in SI (one per metric and condition, e.g. per amplitude or per loop), the data its
figure needs, notes. A unit's run is bit for bit its run alone (the kernel's lanes are
independent). This module holds the step, margins, threshold and no-load-rate tests and the
shared helpers; ``battery_loops`` the hysteresis and load deflection, ``battery_sweeps`` the
frequency response and dynamic stiffness. The limits
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
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from ema_cli.acceptance.measurement import Measurement, TestRun
from ema_cli.config.acceptance import (
    METRICS,
    MarginsTest,
    NoLoadRateTest,
    StepTest,
    ThresholdTest,
)
from ema_cli.sim.tables import MET
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


CHUNK_BYTES = 192 * 2**20  # recorded signals of one kernel call, at most [bytes]


def _simulate(units: Sequence[Mapping[str, float]], signals: list[Any], dt: float,
              duration: float, interval: float | None) -> Iterator[tuple[int, Any]]:
    """Case c runs the SI parameters ``units[c]`` on ``signals[c]`` (or ``signals[0]`` for
    every case when one is given): kernel batches of at most :data:`CHUNK_BYTES` of recorded
    signals (the lanes are independent: the split changes no bit) -> (first case, result)."""
    from ema_cli.model.params import to_row
    from ema_cli.sim.grid import plan_steps
    from ema_cli.sim.runner import simulate_batch
    from ema_cli.sim.tables import N_SIGNALS

    n_steps, dec = plan_steps(duration, dt, interval)
    per_case = ((n_steps // dec + 1) if dec else 1) * N_SIGNALS * 8
    size = max(1, CHUNK_BYTES // per_case)
    for a in range(0, len(units), size):
        rows = units[a:a + size]
        sigs = signals if len(signals) == 1 else signals[a:a + size]
        P = np.array([to_row(r) for r in rows])
        idx = np.zeros(len(rows), dtype=np.int64) if len(sigs) == 1 else np.arange(len(rows))
        yield a, simulate_batch(P, sigs, idx, dt, n_steps, dec, parallel=len(rows) > 1)


def _whole(duration: float, dt: float) -> float:
    """``duration`` rounded up to a whole number of steps ``dt`` [s]."""
    return math.ceil(duration / dt - 1e-9) * dt


def _interval(duration: float, dt: float, samples: int) -> float:
    """A recording interval, a whole number of steps, giving about ``samples`` samples."""
    return max(1, round(duration / samples / dt)) * dt


# ------------------------------------------------------------------------------- the tests
RECORD_SAMPLES = 10000  # recorded samples of a step or no-load-rate run (its figure) [-]


def run_step(name: str, test: StepTest, units: Sequence[Mapping[str, float]],
             dt: float, samples: int = RECORD_SAMPLES) -> list[TestRun]:
    """``samples``: recorded samples per run (the metrics come from the kernel at every step
    whatever it is; only a rise-time bound reads the recorded load angle)."""
    from ema_cli.sim.signals import InputSignal

    duration = _whole(test.duration_s, dt)
    out = []
    for _, res in _simulate(units, [InputSignal(kind="step",
                                                amplitude=test.amplitude_deg * DEG)],
                            dt, duration, _interval(duration, dt, samples)):
        out += [_step_case(name, test, res, c, duration) for c in range(len(res.P))]
    return out


def _step_case(name: str, test: StepTest, res: Any, c: int, duration: float) -> TestRun:
    met = res.metrics[c]
    cond = f"{test.amplitude_deg:g} deg"
    settle, rise = met[MET["settling_time"]], met[MET["rise_time"]]
    notes = ["diverged"] if res.diverged[c] else []
    out = []
    if res.diverged[c] or math.isfinite(settle):
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
            share = res.signal("theta_load", c) / (test.amplitude_deg * DEG)
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
    return TestRun(name, "step", out, {"t": res.t_out, "ref": res.signal("theta_ref", c),
                                       "load": res.signal("theta_load", c),
                                       "amplitude_deg": test.amplitude_deg}, notes=notes)


def run_margins(name: str, test: MarginsTest, units: Sequence[Mapping[str, float]],
                dt: float, figure: bool = True) -> list[TestRun]:
    """The linear limit's margins of each unit (no simulation: ``dt`` unused); ``figure``
    False leaves out the loop transfer functions the figure draws (the measurements are the
    same)."""
    return [_margins(name, test, p, figure) for p in units]


def _margins(name: str, test: MarginsTest, params: Mapping[str, float],
             figure: bool = True) -> TestRun:
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
        if figure:
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


def step_fractions(units: Sequence[Mapping[str, float]], amplitudes: np.ndarray,
                   within_s: float, dt: float) -> np.ndarray:
    """The largest share of the step ``amplitudes[c]`` [rad] the load of ``units[c]`` (SI
    parameters) reaches within ``within_s`` [s] (one kernel batch per memory block)."""
    from ema_cli.sim.signals import InputSignal

    duration = _whole(within_s, dt)
    amplitudes = np.asarray(amplitudes, dtype=float)
    sigs = [InputSignal(kind="step", amplitude=float(a)) for a in amplitudes]
    # the kernel's step_peak: max(theta_L / step) over every step of the run (nothing recorded)
    return np.concatenate([res.metrics[:, MET["step_peak"]]
                           for _, res in _simulate(units, sigs, dt, duration, None)])


def run_threshold(name: str, test: ThresholdTest, units: Sequence[Mapping[str, float]],
                  dt: float) -> list[TestRun]:
    """The k-section search of every unit, each round one batch for every unit still
    searching."""
    lo, hi = (v * DEG for v in test.search_deg)
    tried: list[dict[float, float]] = [{} for _ in units]

    def evaluate(asks: dict[int, np.ndarray]) -> None:
        who = [u for u, amps in asks.items() for _ in amps]
        amps = np.concatenate(list(asks.values()))
        fracs = step_fractions([units[u] for u in who], amps, test.within_s, dt)
        for u, a, frac in zip(who, amps, fracs, strict=True):
            tried[u][float(a)] = float(frac)

    evaluate({u: np.geomspace(lo, hi, THRESHOLD_BATCH) for u in range(len(units))})
    for _ in range(THRESHOLD_ROUNDS):
        asks = {}
        for u in range(len(units)):
            amps = sorted(tried[u])
            ok = [tried[u][a] >= test.fraction for a in amps]
            if all(ok):
                continue
            last_fail = max(k for k, v in enumerate(ok) if not v)
            if last_fail == len(amps) - 1:
                continue
            a_f, a_p = amps[last_fail], amps[last_fail + 1]
            if a_p / a_f - 1.0 <= test.rtol:
                continue
            asks[u] = np.geomspace(a_f, a_p, THRESHOLD_BATCH + 2)[1:-1]
        if not asks:
            break
        evaluate(asks)
    return [_threshold_case(name, test, t, lo, hi) for t in tried]


def _threshold_case(name: str, test: ThresholdTest, tried: dict[float, float], lo: float,
                    hi: float) -> TestRun:
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


def run_no_load_rate(name: str, test: NoLoadRateTest, units: Sequence[Mapping[str, float]],
                     dt: float, samples: int = RECORD_SAMPLES) -> list[TestRun]:
    """``samples``: recorded samples per run (the peak rate is the kernel's, at every step;
    the recorded rate only tells whether the load still accelerated at the end)."""
    from ema_cli.sim.signals import InputSignal

    duration = _whole(test.duration_s, dt)
    cond = f"{test.amplitude_deg:g} deg step"
    out = []
    for _, res in _simulate(units, [InputSignal(kind="step",
                                                amplitude=test.amplitude_deg * DEG)],
                            dt, duration, _interval(duration, dt, samples)):
        for c in range(len(res.P)):
            rate = res.metrics[c, MET["peak_load_rate"]]
            w = np.abs(res.signal("omega_load", c))
            if len(w) > 2 and np.all(np.isfinite(w)) and int(np.argmax(w)) >= len(w) - 2:
                m = _bound("no_load_rate", "rate", cond, rate, math.inf,
                           f"the load was still accelerating at the end of the run, "
                           f"{duration:g} s: lengthen duration_s")
            else:
                m = _m("no_load_rate", "rate", cond, rate)
            out.append(TestRun(name, "no_load_rate", [m],
                               {"t": res.t_out, "rate": res.signal("omega_load", c),
                                "amplitude_deg": test.amplitude_deg},
                               notes=["diverged"] if res.diverged[c] else []))
    return out

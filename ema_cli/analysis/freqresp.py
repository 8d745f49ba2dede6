"""Sinestream frequency response of the (nonlinear) actuator, by simulation.

One simulation per (amplitude, frequency): a sine reference ``A sin(2 pi f t)`` on the load
angle, held for a settling time, then measured over whole periods. Each frequency is snapped to
a period of a whole number of integration steps that is also a whole number of recorded samples
(``SAMPLES_PER_PERIOD``), so a single-bin DFT over whole periods has no leakage. From the
DFT of the load angle against the DFT of the reference over the same window: gain [dB], phase
[deg], and the total harmonic distortion of the load angle (harmonics 2..``HARMONICS``) as the
nonlinearity indicator; from the recorded current and voltage demand and the position error,
which limit was reached (SAT1 load-speed command, SAT2 voltage, SAT3 current).

All amplitudes (and all actuators, for a batch of units) of one frequency run in one kernel
batch. Units: SI inside, degrees and Hz in the results (``FreqPoint``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.sim.tables import SIGNALS
from ema_cli.units import DEG

SAMPLES_PER_PERIOD = 200  # recorded samples per period of the reference [-]
HARMONICS = 10  # highest harmonic in the distortion [-]
SETTLE_S = 0.5  # settling before the measured period [s]
CHANGE_TOL = 1e-3  # the response changed more than this from the period before: run longer [-]
CHECK_FROM = 0.8  # ... the period before, when it starts after this share of SETTLE_S [-]
SETTLE_PERIODS = 3  # the longer run: settle max(this many periods, SETTLE_S) ... [periods]
MEASURE_PERIODS = 4  # ... and measure this many [periods]
LIMIT_TOL = 1e-9  # a limit counts as reached within this relative margin [-]
_COL = {c.name: k for k, c in enumerate(SIGNALS)}


@dataclass(frozen=True)
class FreqPoint:
    """One (amplitude, frequency) of a sinestream: gain [dB] and phase [deg] of the load angle
    against the reference, its harmonic distortion [%], and the limits reached."""

    amplitude_deg: float
    f_hz: float
    gain_db: float
    phase_deg: float
    thd_pct: float
    limits: tuple[str, ...]
    diverged: bool
    periods: int = 1  # measured periods: 1, or MEASURE_PERIODS after a longer run


def snap_frequency(f_hz: float, dt: float) -> tuple[float, int, int]:
    """A frequency within 0.25 % of ``f_hz`` whose period is a whole number of recorded
    samples, each a whole number of steps -> (frequency [Hz], steps per sample, samples per
    period, between :data:`SAMPLES_PER_PERIOD` and twice that, or fewer for a period shorter
    than that many steps)."""
    steps = 1.0 / (f_hz * dt)
    dec = max(1, int(steps // SAMPLES_PER_PERIOD))
    spp = max(1, round(steps / dec))
    return 1.0 / (dec * spp * dt), dec, spp


def sinestream_steps(freqs_hz: Sequence[float], dt: float, n_cases: int = 1) -> float:
    """The integration steps of a sinestream at most (cases x steps, summed over the
    frequencies), computed before any run: each frequency settles :data:`SETTLE_S` and
    measures one period, and when the response is still changing runs again, settling
    max(3 periods, SETTLE_S) and measuring 4 (:func:`_run_frequency`)."""
    total = 0.0
    for f in freqs_hz:
        period_steps = 1.0 / (float(f) * dt)
        settle = max(SETTLE_PERIODS, math.ceil(SETTLE_S * float(f) - 1e-9))
        total += SETTLE_S / dt + period_steps + (settle + MEASURE_PERIODS) * period_steps
    return total * n_cases


@functools.lru_cache(maxsize=4096)
def _kernel(n: int, k: int) -> np.ndarray:
    """``exp(-2 pi i k j / n)``, j = 0..n-1 (read-only: shared by every call)."""
    e = np.exp(-2j * math.pi * k * np.arange(n) / n)
    e.flags.writeable = False
    return e


def _bin(y: np.ndarray, k: int) -> complex:
    """The DFT bin of ``k`` cycles per ``len(y)`` samples, as a complex amplitude."""
    n = len(y)
    return 2.0 / n * complex(np.dot(y, _kernel(n, k)))


CHUNK_BYTES = 192 * 2**20  # recorded signals of one kernel call, at most [bytes]


@dataclass(frozen=True)
class Window:
    """The measured window of one case: ``signals[sample, col]`` over ``periods`` whole
    periods; ``change``, the relative change of the response from the period before the window
    to the window (:func:`period_change`; NaN where that period was not simulated, inf where
    the fixed settling was run); whether the case diverged."""

    signals: np.ndarray
    periods: int
    change: float
    diverged: bool


def response(sig: np.ndarray, inp: str, periods: int) -> complex:
    """The first-harmonic response of the load angle to the input signal ``inp`` over
    ``periods`` whole periods of recorded signals ``sig[sample, col]`` (0 when the load did
    not move)."""
    y = _bin(sig[:, _COL["theta_load"]], periods)
    return y / _bin(sig[:, _COL[inp]], periods) if y else 0j


def period_change(before: np.ndarray, window: np.ndarray, inp: str) -> float:
    """The relative change [-] of the first-harmonic response (:func:`response`) from one
    period ``before`` to the next, ``window`` (0 when neither moved, inf when only one did)."""
    h0, h1 = response(before, inp, 1), response(window, inp, 1)
    if h1 == 0j:
        return 0.0 if h0 == 0j else math.inf
    return abs(h1 - h0) / abs(h1)


def _simulate(rows: Sequence[Mapping[str, float]], refs: list[Any], index: Sequence[int],
              dt: float, n_steps: int, dec: int, first: int, n_samples: int,
              parallel: bool) -> tuple[np.ndarray, np.ndarray]:
    """Run the cases for ``n_steps`` recording every ``dec`` steps, in kernel calls of at most
    :data:`CHUNK_BYTES` of recorded signals (the lanes are independent, so the split changes
    no bit) -> (``signals[case, first:first + n_samples, col]``, diverged[case])."""
    from ema_cli.model.params import to_row
    from ema_cli.sim.runner import simulate_batch
    from ema_cli.sim.tables import N_SIGNALS

    per_case = (n_steps // dec + 1) * N_SIGNALS * 8
    size = max(1, CHUNK_BYTES // per_case)
    windows, diverged = [], []
    for a in range(0, len(rows), size):
        P = np.array([to_row(r) for r in rows[a:a + size]])
        res = simulate_batch(P, refs, np.asarray(index[a:a + size], dtype=np.int64), dt,
                             n_steps, dec, parallel=parallel)
        windows.append(res.signals[:, first:first + n_samples])
        diverged.append(res.diverged)
    return np.concatenate(windows), np.concatenate(diverged)


def _run_frequency(rows: Sequence[Mapping[str, float]], f_req: float,
                   make_refs: Callable[[float], list[Any]], index: Sequence[int], dt: float,
                   parallel: bool, inp: str) -> tuple[float, list[Window]]:
    """Run case c with the SI parameters ``rows[c]`` on ``make_refs(f)[index[c]]``, ``f`` the
    frequency ``f_req`` snapped (:func:`snap_frequency`) -> (snapped frequency [Hz], each
    case's measured :class:`Window`; ``inp``, the input signal's column, for the check).

    Every case settles :data:`SETTLE_S` (the closed loop's transients decay in time, not in
    periods) and one period is measured. Where the settling's last fifth (:data:`CHECK_FROM`)
    holds a whole period (f >= 5 / SETTLE_S), the response over that period is compared with
    the measured one: a case whose response changed by more than :data:`CHANGE_TOL` is still
    settling, or is not periodic at
    the input's period (a limit cycle, stick-slip), and runs again from the start, settling
    max(:data:`SETTLE_PERIODS` periods, SETTLE_S) and measuring :data:`MEASURE_PERIODS`. Each
    case is decided on its own, so its window is the same in any batch. A case that diverged
    keeps its first run (the second would repeat it, longer)."""
    f, dec, spp = snap_frequency(f_req, dt)
    if dec * spp < 8 * (HARMONICS + 1):
        raise EmaError(f"{f_req:g} Hz is too fast for dt = {dt:g} s (a period needs "
                       f"{8 * (HARMONICS + 1)} steps at least)")
    refs = make_refs(f)
    first = math.ceil(SETTLE_S / (dec * dt) - 1e-9)  # samples
    # the period before the window is compared with it when it starts late in the settling
    lead = spp if first - spp >= CHECK_FROM * first else 0
    sig, div = _simulate(rows, refs, index, dt, (first + spp) * dec, dec, first - lead,
                         lead + spp, parallel)
    out: list[Window | None] = [None] * len(rows)
    redo = []
    for c in range(len(rows)):
        win = sig[c, lead:]
        change = period_change(sig[c, :lead], win, inp) if lead else math.nan
        if div[c] or not change > CHANGE_TOL:  # NaN (not checked) passes
            out[c] = Window(win, 1, change, bool(div[c]))
        else:
            redo.append(c)
    if redo:
        settle = max(SETTLE_PERIODS, math.ceil(SETTLE_S * f - 1e-9))
        sig, div = _simulate([rows[c] for c in redo], refs, [index[c] for c in redo], dt,
                             (settle + MEASURE_PERIODS) * dec * spp, dec, settle * spp,
                             MEASURE_PERIODS * spp, parallel)
        for k, c in enumerate(redo):
            out[c] = Window(sig[k], MEASURE_PERIODS, math.inf, bool(div[k]))
    return f, [w for w in out if w is not None]


def _check_positive(values: Sequence[float], what: str, unit: str) -> list[float]:
    out = [float(v) for v in values]
    if not out or any(not (math.isfinite(v) and v > 0) for v in out):
        raise EmaError(f"{what} must be finite numbers > 0 [{unit}], got {list(values)}")
    return out


def sinestream(params: Mapping[str, float], amplitudes_deg: Sequence[float],
               freqs_hz: Sequence[float], dt: float = 1e-5,
               parallel: bool = True) -> list[FreqPoint]:
    """Simulate the sinestream of the SI parameters ``params`` -> one point per amplitude and
    frequency (amplitude-major)."""
    return sinestream_units([params], amplitudes_deg, freqs_hz, dt, parallel)[0]


def sinestream_units(units: Sequence[Mapping[str, float]], amplitudes_deg: Sequence[float],
                     freqs_hz: Sequence[float], dt: float = 1e-5,
                     parallel: bool = True) -> list[list[FreqPoint]]:
    """The sinestream of each actuator of ``units`` (SI parameters), every unit and amplitude
    of one frequency in one kernel batch -> per unit, one point per amplitude and frequency
    (amplitude-major), bit for bit what :func:`sinestream` gives for that unit alone."""
    from ema_cli.progress import report
    from ema_cli.sim.signals import InputSignal

    amps = _check_positive(amplitudes_deg, "amplitudes", "deg")
    freqs = _check_positive(freqs_hz, "frequencies", "Hz")
    rows = [u for u in units for _ in amps]
    index = [i for _ in units for i in range(len(amps))]  # case -> its amplitude's signal
    out: dict[tuple[int, int, int], FreqPoint] = {}
    for j, f_req in enumerate(freqs):
        report("frequencies", j, len(freqs))
        f, wins = _run_frequency(
            rows, f_req, lambda f: [InputSignal(kind="sine", amplitude=a * DEG, freq=f)
                                    for a in amps], index, dt, parallel, "theta_ref")
        for c, p in enumerate(rows):
            u, i = divmod(c, len(amps))
            w = wins[c]
            y = w.signals[:, _COL["theta_load"]]
            y1 = _bin(y, w.periods)
            h = y1 / _bin(w.signals[:, _COL["theta_ref"]], w.periods)
            moved = abs(h) > 0.0  # a load that never leaves a dead band has no response
            out[(u, i, j)] = FreqPoint(amps[i], f, 20.0 * math.log10(abs(h)) if moved
                                       else -math.inf,
                                       math.degrees(math.atan2(h.imag, h.real)) if moved
                                       else math.nan, _thd(y, y1, w.periods),
                                       _limits(p, w.signals), w.diverged, w.periods)
    return [_unwrap([out[(u, i, j)] for i in range(len(amps)) for j in range(len(freqs))],
                    len(freqs)) for u in range(len(units))]


def _thd(y: np.ndarray, y1: complex, periods: int) -> float:
    """Total harmonic distortion of ``y`` [%] (harmonics 2..HARMONICS of the fundamental
    ``y1`` of the measured window, ``periods`` periods long)."""
    harm = [_bin(y, periods * k) for k in range(2, HARMONICS + 1)]
    return 100.0 * math.sqrt(sum(abs(x) ** 2 for x in harm)) / abs(y1) if y1 else math.inf


@dataclass(frozen=True)
class CompliancePoint:
    """One frequency of a load-torque sinestream in closed loop: the compliance
    ``theta_L / T_load`` [rad/(N*m)] (complex), the dynamic stiffness ``|T_load / theta_L|``
    [N*m/rad], the distortion of the load angle [%] and the limits reached."""

    f_hz: float
    compliance: complex
    thd_pct: float
    limits: tuple[str, ...]
    diverged: bool
    periods: int = 1  # measured periods: 1, or MEASURE_PERIODS after a longer run

    @property
    def stiffness(self) -> float:
        return 1.0 / abs(self.compliance) if self.compliance else math.inf


def compliance_stream(params: Mapping[str, float], amplitude_nm: float,
                      freqs_hz: Sequence[float], dt: float = 1e-5,
                      parallel: bool = True) -> list[CompliancePoint]:
    """The closed-loop response of the load angle to a sine load torque ``amplitude_nm``
    [N*m] at each frequency (position reference held at 0), one kernel batch per frequency."""
    return compliance_units([params], amplitude_nm, [freqs_hz], dt, parallel)[0]


def compliance_units(units: Sequence[Mapping[str, float]], amplitude_nm: float,
                     freqs_hz: Sequence[Sequence[float]], dt: float = 1e-5,
                     parallel: bool = True) -> list[list[CompliancePoint]]:
    """:func:`compliance_stream` of each actuator of ``units`` (SI parameters) at its own
    frequencies ``freqs_hz[u]``: the units asking for the same frequency run in one kernel
    batch -> per unit, its points in the order asked, bit for bit what
    :func:`compliance_stream` gives for that unit alone."""
    from ema_cli.progress import report
    from ema_cli.sim.signals import InputSignal

    (amp,) = _check_positive([amplitude_nm], "the load-torque amplitude", "N*m")
    asks = [_check_positive(fs, "frequencies", "Hz") for fs in freqs_hz]
    who: dict[float, list[int]] = {}
    for u, fs in enumerate(asks):
        for f in fs:
            who.setdefault(f, []).append(u)
    got: dict[tuple[int, float], CompliancePoint] = {}
    for j, (f_req, us) in enumerate(who.items()):
        report("frequencies", j, len(who))
        f, wins = _run_frequency(
            [units[u] for u in us], f_req,
            lambda f: [InputSignal(kind="step", amplitude=0.0, load_sine=(amp, f))],
            [0] * len(us), dt, parallel, "torque_load")
        for c, u in enumerate(us):
            w = wins[c]
            y = w.signals[:, _COL["theta_load"]]
            y1 = _bin(y, w.periods)
            z = y1 / _bin(w.signals[:, _COL["torque_load"]], w.periods)
            got[(u, f_req)] = CompliancePoint(f, z, _thd(y, y1, w.periods),
                                              _limits(units[u], w.signals), w.diverged,
                                              w.periods)
    return [[got[(u, f)] for f in fs] for u, fs in enumerate(asks)]


def _limits(p: Mapping[str, float], sig: np.ndarray) -> tuple[str, ...]:
    """The saturations reached in the measured window (SAT1 from the position error)."""
    reached = []
    b = p.get("fb_motor", 0.0)  # the position fed back (docs/model.md: controller)
    e = sig[:, _COL["theta_ref"]] - ((1.0 - b) * sig[:, _COL["theta_load"]]
                                     + b * sig[:, _COL["theta_motor"]])
    if np.max(np.abs(p["Kpp"] * e)) >= p["sat1"] * (1 - LIMIT_TOL):
        reached.append("sat1")
    if np.max(np.abs(sig[:, _COL["voltage_cmd"]])) >= p["sat2"] * (1 - LIMIT_TOL):
        reached.append("sat2")
    if np.max(np.abs(sig[:, _COL["current"]])) >= p["sat3"] * (1 - LIMIT_TOL):
        reached.append("sat3")
    return tuple(reached)


def _unwrap(points: list[FreqPoint], n_freq: int) -> list[FreqPoint]:
    """Phases continuous along frequency within each amplitude (starting in (-180, 180]),
    NaN phases (no response) skipped."""
    out = []
    for start in range(0, len(points), n_freq):
        block = points[start:start + n_freq]
        phase = np.array([p.phase_deg for p in block])
        ok = np.isfinite(phase)  # NaN where the load did not move: left out of the unwrapping
        phase[ok] = np.degrees(np.unwrap(np.radians(phase[ok])))
        out += [FreqPoint(p.amplitude_deg, p.f_hz, p.gain_db, float(ph), p.thd_pct, p.limits,
                          p.diverged, p.periods) for p, ph in zip(block, phase, strict=True)]
    return out


LIMITS = ("sat1", "sat2", "sat3")
LIMIT_NAMES = {"sat1": "SAT1 load-speed command (rate limit)", "sat2": "SAT2 voltage demand",
               "sat3": "SAT3 current"}


def limit_amplitudes(params: Mapping[str, float], f_hz: np.ndarray) -> dict[str, np.ndarray]:
    """The linear model's estimate of the reference amplitude [deg] at which each saturation is
    first reached by a sine of frequency ``f_hz`` [Hz]: SAT1 ``sat1/(Kpp |1 - H|)`` (H: the
    response of the position fed back, so ``1 - H`` is the position error), SAT2 ``sat2/|U|``
    (voltage demand), SAT3 ``sat3/|I|`` (current), U and I the closed-loop responses of the
    voltage demand and the current to the reference. Below these amplitudes the actuator is
    linear (no limit reached)."""
    from ema_cli.analysis.linear import linear_model

    ss = linear_model(params)
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    b = params.get("fb_motor", 0.0)  # the position fed back: (1-b)*theta_L + b*theta_m/m
    h = (1.0 - b) * ss.response(f) + b / params["m"] * ss.response(f, out="theta_m")
    with np.errstate(divide="ignore"):
        return {
            "sat1": params["sat1"] / (params["Kpp"] * np.abs(1.0 - h)) / DEG,
            "sat2": params["sat2"] / np.abs(ss.response(f, out="u_dem")) / DEG,
            "sat3": params["sat3"] / np.abs(ss.response(f, out="i")) / DEG,
        }


def limit_onsets(points: Sequence[FreqPoint]) -> dict[str, float]:
    """The lowest frequency [Hz] at which each limit was reached in one amplitude's points."""
    out: dict[str, float] = {}
    for p in sorted(points, key=lambda q: q.f_hz):
        for lim in p.limits:
            out.setdefault(lim, p.f_hz)
    return {k: out[k] for k in LIMITS if k in out}


def binding_limit(points: Sequence[FreqPoint], f_3db_hz: float) -> str | None:
    """The limit that shapes the bandwidth of one amplitude: of the limits reached at or
    below the first frequency at or above the -3 dB bandwidth ``f_3db_hz`` (every frequency
    if there is no -3 dB crossing), the one reached at the lowest frequency (None: no limit is
    reached there, the bandwidth is the linear one)."""
    pts = sorted(points, key=lambda q: q.f_hz)
    if math.isfinite(f_3db_hz):
        above = [p.f_hz for p in pts if p.f_hz >= f_3db_hz]
        if above:
            pts = [p for p in pts if p.f_hz <= above[0]]
    onsets = limit_onsets(pts)
    if not onsets:
        return None
    return min(onsets, key=lambda k: (onsets[k], LIMITS.index(k)))


def crossing(f_hz: np.ndarray, y: np.ndarray, level: float) -> float:
    """The first frequency where ``y`` falls through ``level``, interpolated on log f (NaN if
    it never does)."""
    for k in range(len(y) - 1):
        if y[k] >= level > y[k + 1]:
            w = (y[k] - level) / (y[k] - y[k + 1])
            return float(math.exp(math.log(f_hz[k]) + w * math.log(f_hz[k + 1] / f_hz[k])))
    return math.nan

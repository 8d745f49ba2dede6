"""Output-error identification from a closed-loop log: the whole simulator fitted to the
measured load angle (and motor speed, current, voltage demand) for a logged command.

The log (``t_s, theta_ref_deg, theta_load_deg`` and optionally ``omega_motor_rpm,
current_a, voltage_cmd_v``; uniform or not) is validated by :func:`load_log`. The simulator
runs on its own fixed step ``dt`` from rest at t = 0 (the log's first time stamp), following
the logged command as a ``csv`` reference (linear between the samples); its recorded signals
are compared at the log's time stamps (read straight off the record when every stamp is on
the recording grid, else interpolated linearly from a record at least twice as fine as the
log). The cost is the weighted sum of squared output errors::

    J(x) = sum_c sum_i ((y_c,i - yhat_c,i(x)) / s_c)^2          [-]

with ``s_c`` the channel's scale (its noise estimate by default, :func:`noise_estimate`).
``evaluate(X[n_pop, n_free])`` simulates the whole population in one batched kernel call
(``sim.runner.simulate_batch``), the interface the GA (``optim.ga``) minimises.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.identify.friction.sweep import read_truth
from ema_cli.identify.logs.channels import read_log
from ema_cli.model.params import BY_NAME, resolve, to_row
from ema_cli.units import DEG, RPM

LOG_REQUIRED = ("t_s", "theta_ref_deg", "theta_load_deg")
LOG_OPTIONAL = ("omega_motor_rpm", "current_a", "voltage_cmd_v")
CHANNELS: dict[str, tuple[str, float, str]] = {
    "theta_load_deg": ("theta_load", DEG, "deg"),
    "omega_motor_rpm": ("omega_motor", RPM, "rpm"),
    "current_a": ("current", 1.0, "A"),
    "voltage_cmd_v": ("voltage_cmd", 1.0, "V"),
}
"""Measured channel (log column) -> (simulator signal, edge -> SI factor, edge unit)."""
FREE_NAMES = ("kL", "alpha", "zeta_t", "c", "contact_tau", "contact_hc", "Fc", "Fs", "vs",
              "sigma2", "sigma0", "Jm", "JL", "bL")
"""Parameters a closed-loop fit may free (names of ``ema params``)."""
FRICTION_NAMES = ("Fc", "Fs", "vs", "sigma2", "sigma0")
DEFAULT_FREE: dict[str, tuple[float, float]] = {
    "kL": (300.0, 900.0), "alpha": (0.0, 0.01), "Fc": (0.0, 0.1), "sigma2": (0.0, 0.1)}
"""The free set without a config: bounds in SI (N*m/rad, rad, N*m, N*m*s/rad)."""
NUISANCE: dict[str, tuple[float, float]] = {"zeta_t": (0.02, 1.0), "contact_tau": (0.0, 1e-3),
                                            "contact_hc": (0.0, 1.0)}
"""The contact's parameters freed by a multiple-shooting fit unless stated (settings
``free_contact``): SI bounds (-, s, -): its damping, the damping's ramp-in time and its
Hunt-Crossley share (damping growing with the penetration; docs/model.md §1). Reported, but
neither the verdict's bound rule nor its "not determined" applies to them: a contact on a
physical bound (tau = 0: the jump law) is an answer, and the primary parameters' intervals
already carry their correlation with them."""
CONTACT_SHAPE = ("contact_tau", "contact_hc")
"""The contact law's shape: stating one of them (plant or free) states the law, and the others
keep their model values (``contact_tau = 0`` alone is the jump law, with no Hunt-Crossley
share)."""
MIN_LOG_ROWS = 50  # fewest samples accepted in a log [rows]
MIN_LOG_DURATION_S = 0.05  # shortest log accepted [s]
MIN_POSITIVE = {"Fc": 1e-9, "vs": 1e-9, "Jm": 1e-12, "JL": 1e-12}
"""Where a free parameter's bound reaches 0 but the model needs > 0 (LuGre needs Fc, vs > 0;
inertias > 0), the value simulated is at least this [SI]."""
ON_GRID_TOL = 1e-6  # a time stamp within 1e-6 steps of the grid is on it [steps]
COMMAND_SUBSAMPLES = 8  # points per log interval of a cubic command table [-]
OVERSAMPLE = 2  # record at least this many samples per log interval when interpolating [-]
MAX_RECORD_BYTES = 2**28  # the record of one population batch at most (else interpolate) [B]
FAILED_RESIDUAL = 1e6  # weighted residual of a diverged simulation (least-squares polish) [-]


@dataclass
class KernelWork:
    """The kernel work of a whole multiple-shooting fit: every problem derived from the
    search's (longer segments, the covariance's split) adds to the same one."""

    evaluations: int = 0  # simulated segment runs
    kernel_steps: int = 0  # lane-steps
    kernel_s: float = 0.0  # seconds in the kernel

    def add(self, evaluations: int, kernel_steps: int, kernel_s: float) -> None:
        self.evaluations += evaluations
        self.kernel_steps += kernel_steps
        self.kernel_s += kernel_s


@dataclass(frozen=True)
class ClosedLoopLog:
    """A validated closed-loop log, SI: times from 0 [s], command [rad], measured channels."""

    t: np.ndarray
    theta_ref: np.ndarray
    channels: dict[str, np.ndarray]
    source: str
    t0: float = 0.0
    truth: dict[str, float] | None = None

    @property
    def n(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1])


def load_log(path: str | Path, *, columns: Mapping[str, str] | None = None,
             window: Sequence[float] | None = None) -> ClosedLoopLog:
    """Read and validate a closed-loop log: CSV, Parquet or MATLAB .mat
    (``identify.logs.channels``),
    its columns found through the map ``columns`` (channel -> ``COLUMN[:UNIT]``), only the
    samples with ``window[0] <= t <= window[1]`` [s, the log's own time] kept. Errors name the
    file, the column and the line (CSV), row (Parquet) or index (MATLAB): missing columns,
    empty/non-numeric/NaN/inf values, time not strictly increasing, a window outside the log,
    fewer than :data:`MIN_LOG_ROWS` rows or shorter than :data:`MIN_LOG_DURATION_S`, a constant
    channel. ``t0`` is the first time stamp kept; ``t`` starts at 0."""
    p = Path(path)
    cols = read_log(p, LOG_REQUIRED, LOG_OPTIONAL, columns)
    where = cols.table.where
    t = cols.values["t_s"]
    n = t.shape[0]
    if n < MIN_LOG_ROWS:
        raise EmaError(f"data file '{p}' has {n} data rows; a closed-loop log needs at least "
                       f"{MIN_LOG_ROWS}")
    steps = np.diff(t)
    if np.any(steps <= 0):
        i = int(np.flatnonzero(steps <= 0)[0]) + 1  # the second sample of the pair
        raise EmaError(f"data file '{p}': {cols.label('t_s')} must be strictly increasing; it "
                       f"is not at {where(i)} (t_s = {t[i]:g} after {t[i - 1]:g})")
    values = dict(cols.values)
    source = f"file: {p}"
    if window is not None:
        keep = window_mask(t, window, p)
        values = {k: v[keep] for k, v in values.items()}
        t = values["t_s"]
        source += f" (window {window[0]:g} .. {window[1]:g} s)"
    if t[-1] - t[0] < MIN_LOG_DURATION_S:
        raise EmaError(f"data file '{p}' spans {t[-1] - t[0]:g} s; a closed-loop log must "
                       f"span at least {MIN_LOG_DURATION_S:g} s")
    if np.ptp(values["theta_ref_deg"]) == 0:
        raise EmaError(f"data file '{p}': {cols.label('theta_ref_deg')} is constant: the "
                       "command does not excite the actuator")
    channels = {}
    for name in ("theta_load_deg", *cols.present):
        y = values[name]
        if np.ptp(y) == 0:
            raise EmaError(f"data file '{p}': {cols.label(name)} is constant "
                           f"({y[0] / CHANNELS[name][1]:g} {CHANNELS[name][2]}); drop it or "
                           "check the logger")
        channels[name] = y
    return ClosedLoopLog(t - t[0], values["theta_ref_deg"], channels, source, float(t[0]),
                         read_truth(p))


WINDOW_SLACK = 0.5  # a window edge may pass the log's ends by this many median intervals [-]


def window_mask(t: np.ndarray, window: Sequence[float], path: Path) -> np.ndarray:
    """The samples of times ``t`` [s] inside ``window`` = (T0, T1) [s]: T0 <= t <= T1. Refuses
    (EmaError naming the option, the file and the log's span) T0 >= T1, a window that passes
    the log's ends by more than WINDOW_SLACK sample intervals, or one keeping fewer than
    :data:`MIN_LOG_ROWS` samples."""
    lo, hi = (float(window[0]), float(window[1]))
    opt = f"--window {lo:g},{hi:g}"
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise EmaError(f"{opt} (data file '{path}'): expected T0 < T1, two finite times in "
                       "seconds")
    slack = WINDOW_SLACK * float(np.median(np.diff(t)))
    if lo < t[0] - slack or hi > t[-1] + slack:
        raise EmaError(f"{opt}: the window passes the ends of data file '{path}', which spans "
                       f"{t[0]:g} .. {t[-1]:g} s (the log's own time)")
    keep = (t >= lo) & (t <= hi)
    n = int(keep.sum())
    if n < MIN_LOG_ROWS:
        raise EmaError(f"{opt}: the window keeps {n} sample(s) of data file '{path}'; a "
                       f"closed-loop log needs at least {MIN_LOG_ROWS}")
    return keep


def noise_estimate(y: np.ndarray, t: np.ndarray) -> float:
    """A noise level of a sampled signal [its unit]: the robust (MAD) standard deviation of
    its second differences over ``sqrt(6)`` (white noise of std s gives differences of std
    ``s*sqrt(6)``; a smooth signal sampled finely adds little). Uniform or not: the
    differences are those of the samples as logged."""
    d2 = y[2:] - 2.0 * y[1:-1] + y[:-2]
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


SCALE_FLOOR = 1e-4  # a channel's scale is at least this fraction of its range [-]
NOISE_NOTE = "noise estimate (MAD of second differences / sqrt 6)"  # how an auto scale was chosen
FLOOR_NOTE = f"{SCALE_FLOOR:g} x range (noise estimate below it)"  # ... for noise-free data


def channel_scale(y: np.ndarray, t: np.ndarray) -> tuple[float, str]:
    """The default weight scale of a channel -> (scale [SI], how it was chosen): the noise
    estimate, or ``SCALE_FLOOR`` x its range when the noise is below that (noise-free data)."""
    noise = noise_estimate(y, t)
    floor = SCALE_FLOOR * float(np.ptp(y))
    if noise >= floor:
        return noise, NOISE_NOTE
    return floor, FLOOR_NOTE


@dataclass(frozen=True)
class Grid:
    """The simulation grid of a fit at one step: steps, record decimation, how to sample."""

    dt: float
    n_steps: int
    dec: int
    index: np.ndarray | None  # record index of every log sample (exact), or None (interpolate)


def make_grid(t: np.ndarray, dt: float, n_cases: int) -> Grid:
    """Plan the steps and the record for log times ``t`` [s] (from 0) at step ``dt`` [s]."""
    k = t / dt
    n_steps = int(math.ceil(k[-1] - ON_GRID_TOL))
    on = np.abs(k - np.round(k)) <= ON_GRID_TOL
    if np.all(on):
        ki = np.round(k).astype(np.int64)
        dec = int(np.gcd.reduce(np.diff(ki))) if ki.shape[0] > 1 else 1
        dec = max(dec, 1)
        n_out = n_steps // dec + 1
        if n_cases * n_out * 17 * 8 <= MAX_RECORD_BYTES:
            return Grid(dt, n_steps, dec, ki // dec)
    h = float(np.median(np.diff(t)))
    dec = max(1, int(h / dt / OVERSAMPLE))
    return Grid(dt, n_steps, dec, None)


@dataclass
class ClosedLoopProblem:
    """Output-error cost of a closed-loop log over the free parameters (SI).

    names[p], lower[p], upper[p]   free parameters and their bounds
    fixed                          plant overrides (SI, ``ema params`` names) held fixed
    channels                       the log columns fitted
    scales[n_ch]                   the channel scales s_c [SI]
    dt, ga_dt                      the fine step (polish, uncertainty) and the GA's step [s]
    """

    log: ClosedLoopLog
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    fixed: dict[str, Any]
    channels: tuple[str, ...]
    scales: np.ndarray
    dt: float
    ga_dt: float
    command: str = "linear"
    evaluations: int = 0
    kernel_steps: int = 0
    kernel_s: float = 0.0
    _refs: dict = field(default_factory=dict, repr=False)

    def command_table(self, a: int = 0, b: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The command between log samples ``a`` and ``b`` (inclusive; default the whole log)
        as a table the simulator interpolates linearly -> (t [s], theta_ref [rad]).
        ``command`` linear: the samples themselves; cubic: a not-a-knot cubic spline through
        every sample of the log, tabulated at :data:`COMMAND_SUBSAMPLES` points per
        interval (a smooth command known only at its samples: read linearly, as the
        simulator reads a table, the samples miss a 5 deg chirp at 8 Hz sampled at 1 kHz by
        up to 2.7e-5 rad, this table by 4.2e-7 rad, 1/64 of it)."""
        lg = self.log
        b = lg.n - 1 if b is None else b
        tt = lg.t[a:b + 1]
        spline = self._command_spline()
        if spline is None or tt.shape[0] < 2:
            return tt, lg.theta_ref[a:b + 1]
        frac = np.arange(COMMAND_SUBSAMPLES) / COMMAND_SUBSAMPLES
        td = np.concatenate([(tt[:-1, None] + np.diff(tt)[:, None] * frac[None]).ravel(),
                             tt[-1:]])
        rd = spline(td)
        k = np.arange(0, td.shape[0], COMMAND_SUBSAMPLES)
        rd[k] = lg.theta_ref[a:b + 1]  # the samples exactly
        return td, rd

    def _command_spline(self) -> Any:
        """The cubic spline through every command sample of the log (built once), or None
        (``command`` linear, or fewer than 4 samples)."""
        if self.command == "linear" or self.log.n < 4:
            return None
        if "spline" not in self._refs:
            from scipy.interpolate import CubicSpline

            self._refs["spline"] = CubicSpline(self.log.t, self.log.theta_ref)
        return self._refs["spline"]

    def params(self, x: np.ndarray) -> dict[str, float]:
        """The complete SI parameters of one free vector (derived ones re-derived: Fs = 1.5 Fc,
        sigma0 = 1e3 Fc, sigma1 from sigma0, c from zeta_t, unless fixed or free)."""
        over = dict(self.fixed)
        for n, v in zip(self.names, x, strict=True):
            over[n] = max(float(v), MIN_POSITIVE.get(n, 0.0))
        if any(n in FRICTION_NAMES for n in self.names):
            over["friction"] = 1.0
        return resolve(over)

    def rows(self, X: np.ndarray) -> np.ndarray:
        """The parameter matrix P[n, N_PARAMS] of a population X[n, p]."""
        return np.array([to_row(self.params(x)) for x in X])

    def _reference(self, dt: float, n_steps: int) -> Any:
        from ema_cli.sim.signals import InputSignal, Sampler

        key = (dt, n_steps)
        if key not in self._refs:
            tt, rr = self.command_table()
            sig = InputSignal("csv", table=(tuple(tt.tolist()), tuple(rr.tolist())),
                              path=self.log.source)
            self._refs[key] = Sampler(sig, dt, n_steps)
        return self._refs[key]

    def predict(self, X: np.ndarray, dt: float | None = None) -> np.ndarray:
        """Simulated channels at the log's times, ``Y[n, n_ch, n_samples]`` (SI; NaN where a
        simulation diverged), all rows in one batched kernel call at step ``dt``."""
        from ema_cli.sim.runner import simulate_batch
        from ema_cli.sim.tables import SIG

        dt = self.dt if dt is None else dt
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        grid = make_grid(self.log.t, dt, X.shape[0])
        P = self.rows(X)
        idx = [SIG[CHANNELS[c][0]] for c in self.channels]
        res = simulate_batch(P, [self._reference(dt, grid.n_steps)], None, dt, grid.n_steps,
                             grid.dec, parallel=True, n_signals=max(idx) + 1)  # what is read
        self.evaluations += X.shape[0]
        self.kernel_steps += X.shape[0] * grid.n_steps
        self.kernel_s += res.kernel_s
        sig = res.signals
        if grid.index is not None:
            Y = sig[:, grid.index, :][:, :, idx].transpose(0, 2, 1)
        else:
            Y = np.empty((X.shape[0], len(idx), self.log.n))
            for i in range(X.shape[0]):
                for j, s in enumerate(idx):
                    Y[i, j] = np.interp(self.log.t, res.t_out, sig[i, :, s])
        Y = np.array(Y)
        Y[res.diverged] = np.nan
        return Y

    @property
    def measured(self) -> np.ndarray:
        """The measured channels ``[n_ch, n_samples]`` (SI)."""
        return np.array([self.log.channels[c] for c in self.channels])

    def weighted_residuals(self, X: np.ndarray, dt: float | None = None) -> np.ndarray:
        """``(y - yhat)/s_c`` flattened channel after channel, ``R[n, n_ch*n_samples]``;
        a diverged row is :data:`FAILED_RESIDUAL` everywhere."""
        Y = self.predict(X, dt)
        R = (self.measured[None] - Y) / self.scales[None, :, None]
        R = R.reshape(R.shape[0], -1)
        return np.where(np.isfinite(R), R, FAILED_RESIDUAL)

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        """J[n_pop] of a population at the GA's step, one kernel call (``inf``: diverged)."""
        Y = self.predict(X, self.ga_dt)
        R = (self.measured[None] - Y) / self.scales[None, :, None]
        J = np.sum(R.reshape(R.shape[0], -1) ** 2, axis=1)
        return np.where(np.isfinite(J), J, np.inf)

    def prefix(self, t_end: float) -> ClosedLoopProblem:
        """The same problem (free set, bounds, channels, scales, steps, the command between
        the samples) on the log's samples up to ``t_end`` [s] (at least :data:`MIN_LOG_ROWS`
        of them), with fresh counters."""
        lg = self.log
        k = max(int(np.searchsorted(lg.t, t_end * (1.0 + 1e-12), side="right")), MIN_LOG_ROWS)
        if k >= lg.n:
            return dataclasses.replace(self, evaluations=0, kernel_steps=0, kernel_s=0.0,
                                       _refs={})
        cut = ClosedLoopLog(lg.t[:k], lg.theta_ref[:k], {c: y[:k] for c, y in lg.channels.items()},
                            lg.source, lg.t0, lg.truth)
        spline = self._command_spline()  # the whole log's: the prefix's command is its own
        keep = {} if spline is None else {"spline": spline}
        return dataclasses.replace(self, log=cut, evaluations=0, kernel_steps=0, kernel_s=0.0,
                                   _refs=keep)

    def groups(self) -> list[slice]:
        """The residual slices of each channel (in ``weighted_residuals``)."""
        n = self.log.n
        return [slice(j * n, (j + 1) * n) for j in range(len(self.channels))]


def check_free(free: Mapping[str, Sequence[float]], fixed: Mapping[str, Any],
               where: str = "free") -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Validate the free parameters and bounds -> (names, lower, upper). Errors name ``where``
    and the parameter: unknown names, LO >= HI, negative or non-finite bounds, a parameter both
    free and fixed, zeta_t and c both free."""
    names, lo, hi = [], [], []
    if not free:
        raise EmaError(f"{where}: no free parameters; free at least one of "
                       f"{', '.join(FREE_NAMES)}")
    for n, b in free.items():
        if n not in FREE_NAMES:
            raise EmaError(f"{where}.{n}: not a parameter a closed-loop fit can free; expected "
                           f"one of {', '.join(FREE_NAMES)}")
        try:
            a, z = (float(b[0]), float(b[1]))
            if len(b) != 2:
                raise ValueError
        except (TypeError, ValueError, IndexError):
            raise EmaError(f"{where}.{n}: expected bounds [LO, HI] in {BY_NAME[n].unit}, got "
                           f"{b!r}") from None
        if not (math.isfinite(a) and math.isfinite(z)):
            raise EmaError(f"{where}.{n}: bounds must be finite, got [{a:g}, {z:g}]")
        if a < 0:
            raise EmaError(f"{where}.{n}: the lower bound must be >= 0 ({BY_NAME[n].unit}), "
                           f"got {a:g}")
        if not z > a:
            raise EmaError(f"{where}.{n}: needs LO < HI, got [{a:g}, {z:g}] {BY_NAME[n].unit}")
        if n in fixed:
            raise EmaError(f"{where}.{n}: {n} is also fixed by plant.{n}; free it or fix it, "
                           "not both")
        names.append(n)
        lo.append(a)
        hi.append(z)
    if "zeta_t" in names and "c" in names:
        raise EmaError(f"{where}: free zeta_t or c, not both (c = 2*zeta_t*sqrt(kL*Jeq) unless "
                       "c is given)")
    return tuple(names), np.array(lo), np.array(hi)

"""Position reference signals (step, ramp, sine, chirp, CSV profile) sampled for the RK4 kernel.

A reference is sampled at every half step (``t = j*dt/2``, ``j = 0..2*n_steps``) so the RK4
stages see it exactly; its velocity (for the velocity-error metrics) at every full step.
All values SI (rad, rad/s, s).

The kernel runs in time chunks: :func:`sampler` prepares a signal for one time grid and its
:meth:`Sampler.chunk` samples any range of steps on demand, bit for bit the values
:func:`sample` gives for the whole run at once, so memory does not grow with the duration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.files import read_csv
from ema_cli.units import DEG

KINDS = ("step", "ramp", "sine", "chirp", "csv")


@dataclass(frozen=True)
class InputSignal:
    """A reference signal in SI units.

    kind      step | ramp | sine | chirp | csv
    amplitude step size / sine and chirp amplitude [rad]
    start     time the signal starts [s] (before it: 0)
    rate      ramp slope [rad/s]; the ramp stops at ``|amplitude|`` in the rate's direction
              (the sign of ``amplitude`` is not used), or never if ``amplitude`` is 0
    freq      sine frequency [Hz]; chirp start frequency
    freq_end  chirp end frequency [Hz] (linear sweep over ``sweep_time``)
    sweep_time chirp sweep duration [s] (0: the run's duration)
    offset    constant added to sine/chirp [rad]
    path      CSV file with columns t_s, theta_ref_deg (csv kind)
    load_table external load-torque profile ((t [s], ...), (torque [N*m], ...)), linearly
              interpolated, its end values held outside it; None: no profile
    load_path  the CSV the profile came from (for reports)
    load_sine  (amplitude [N*m], frequency [Hz]): a sine load torque ``A sin(2 pi f t)`` from
              t = 0, added to the profile; None: none

    ext_table  the input signal ((t [s], ...), (value, ...)): a disturbance added to the
              controller's output (``dist_out``) or, with no controller, the actuation itself
              (``plant_input``: a command, a force or a current); held between its samples
              (``ext_hold``, a logged DAC output) or interpolated linearly; its end values held
    ext_name  where it came from (for reports)

    The signal carries every time-varying input of a run: the position reference and, when
    given, the load-torque profile (``plant.load_torque_nb``) and the input signal.
    """

    kind: str = "step"
    amplitude: float = 20.0 * DEG
    start: float = 0.0
    rate: float = 0.0
    freq: float = 1.0
    freq_end: float = 1.0
    sweep_time: float = 0.0
    offset: float = 0.0
    path: str | None = None
    table: tuple[tuple[float, ...], tuple[float, ...]] | None = field(default=None, repr=False)
    load_table: tuple[tuple[float, ...], tuple[float, ...]] | None = field(default=None,
                                                                          repr=False)
    load_path: str | None = None
    load_sine: tuple[float, float] | None = None
    ext_table: tuple[tuple[float, ...], tuple[float, ...]] | None = field(default=None,
                                                                         repr=False)
    ext_hold: bool = True
    ext_name: str | None = None

    def describe(self) -> str:
        """A short human description in the paper's units."""
        a = self.amplitude / DEG
        if self.kind == "step":
            return f"{a:g} deg step at t = {self.start:g} s"
        if self.kind == "ramp":
            end = (f" to {math.copysign(abs(a), self.rate):g} deg" if self.amplitude != 0
                   else "")
            return f"ramp {self.rate / DEG:g} deg/s from t = {self.start:g} s{end}"
        if self.kind == "sine":
            return f"sine {a:g} deg, {self.freq:g} Hz"
        if self.kind == "chirp":
            return f"chirp {a:g} deg, {self.freq:g} -> {self.freq_end:g} Hz"
        return f"profile {Path(self.path).name if self.path else ''}"


def load_profile(path: str | Path, value: str = "theta_ref_deg",
                 scale: float = DEG) -> tuple[np.ndarray, np.ndarray]:
    """Read a CSV profile (columns ``t_s`` and ``value``) -> (t [s], value*scale), validated.

    The reference profile has ``theta_ref_deg`` (returned in rad); the load-torque profile
    ``torque_nm`` (``scale`` 1).
    """
    import pandas as pd

    p = Path(path)
    df = read_csv(p, "profile", f" (a CSV with columns t_s, {value})")
    missing = [c for c in ("t_s", value) if c not in df.columns]
    if missing:
        raise EmaError(f"profile '{p}' lacks column(s) {missing}; expected t_s, {value}")
    t = pd.to_numeric(df["t_s"], errors="coerce").to_numpy(float)
    y = pd.to_numeric(df[value], errors="coerce").to_numpy(float)
    if len(t) < 2:
        raise EmaError(f"profile '{p}' needs at least 2 rows, has {len(t)}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise EmaError(f"profile '{p}' has empty, non-numeric, NaN or inf values")
    if np.any(np.diff(t) <= 0):
        raise EmaError(f"profile '{p}': t_s must be strictly increasing")
    return t, y * scale


def _position(sig: InputSignal, t: np.ndarray, duration: float,
              table: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    tau = t - sig.start
    on = tau >= 0.0
    if sig.kind == "step":
        return np.where(on, sig.amplitude, 0.0)
    if sig.kind == "ramp":
        y = np.where(on, sig.rate * tau, 0.0)
        if sig.amplitude != 0:  # stops |amplitude| away from the start, in the rate's direction
            y = np.clip(y, -abs(sig.amplitude), abs(sig.amplitude))
        return y
    if sig.kind == "sine":
        return np.where(on, sig.offset + sig.amplitude * np.sin(2 * math.pi * sig.freq * tau), 0.0)
    if sig.kind == "chirp":
        T = sig.sweep_time or max(duration - sig.start, 1e-12)
        tc = np.minimum(tau, T)
        k = (sig.freq_end - sig.freq) / T
        phase = 2 * math.pi * (sig.freq * tc + 0.5 * k * tc**2)
        phase = phase + np.where(tau > T, 2 * math.pi * sig.freq_end * (tau - T), 0.0)
        return np.where(on, sig.offset + sig.amplitude * np.sin(phase), 0.0)
    if sig.kind == "csv":
        tt, yy = table if table is not None else _profile(sig)
        return np.interp(t, tt, yy)
    raise EmaError(f"unknown input kind '{sig.kind}'; expected one of {KINDS}")


def _profile(sig: InputSignal) -> tuple[np.ndarray, np.ndarray]:
    """The (t, theta_ref) table of a ``csv`` signal: its ``table``, else read from ``path``."""
    if sig.table is None:
        return load_profile(sig.path or "")
    return np.asarray(sig.table[0]), np.asarray(sig.table[1])


def _velocity(sig: InputSignal, t: np.ndarray, duration: float) -> np.ndarray:
    """The velocity of a step, ramp, sine or chirp at ``t`` (a CSV profile's comes from
    finite differences: :meth:`Sampler._csv_velocity`)."""
    tau = t - sig.start
    on = tau >= 0.0
    if sig.kind == "step":
        return np.zeros_like(t)
    if sig.kind == "ramp":
        moving = on & ((sig.amplitude == 0) | (np.abs(sig.rate * tau) < abs(sig.amplitude)))
        return np.where(moving, sig.rate, 0.0)
    if sig.kind == "sine":
        w = 2 * math.pi * sig.freq
        return np.where(on, sig.amplitude * w * np.cos(w * tau), 0.0)
    if sig.kind == "chirp":
        T = sig.sweep_time or max(duration - sig.start, 1e-12)
        tc = np.minimum(tau, T)
        k = (sig.freq_end - sig.freq) / T
        phase = 2 * math.pi * (sig.freq * tc + 0.5 * k * tc**2)
        phase = phase + np.where(tau > T, 2 * math.pi * sig.freq_end * (tau - T), 0.0)
        f = np.where(tau > T, sig.freq_end, sig.freq + k * tc)
        return np.where(on, sig.amplitude * 2 * math.pi * f * np.cos(phase), 0.0)
    raise EmaError(f"no closed-form velocity for input kind '{sig.kind}'")


@dataclass(frozen=True)
class Reference:
    """A sampled reference for the kernel.

    pos_half[2*n_steps+1]  position at t = j*dt/2 [rad]
    vel[n_steps+1]         velocity at t = k*dt [rad/s]
    step_info[3]           (is_step, final value [rad], step time [s]) for the step metrics
    load_half[2*n_steps+1] external load-torque profile at t = j*dt/2 [N*m], or None (none)
    ext_half[2*n_steps+1]  the input signal at t = j*dt/2, or None (none)
    """

    pos_half: np.ndarray
    vel: np.ndarray
    step_info: np.ndarray
    load_half: np.ndarray | None = None
    ext_half: np.ndarray | None = None
    ext_hold: bool = True


SCAN_STEPS = 2**16  # steps per block when a whole run's grid is scanned [steps]


def _uniform_grid(dt: float, n_steps: int) -> bool:
    """Whether every step of the grid ``t_k = k*dt`` is exactly ``dt`` in floating point (the
    test ``np.gradient`` applies to the whole grid), scanned block by block."""
    for k0 in range(0, n_steps, SCAN_STEPS):
        t = np.arange(k0, min(k0 + SCAN_STEPS, n_steps) + 1) * dt
        if not np.all(np.diff(t) == dt):
            return False
    return True


class Sampler:
    """A signal prepared for the grid ``t_k = k*dt``, ``k = 0..n_steps``: CSV tables read once,
    then :meth:`chunk` samples any range of steps.

    ``step_info[3]`` (is_step, final value [rad], step time [s]) for the step metrics;
    ``has_load`` whether a load-torque profile is given. ``memo``: keep every chunk sampled
    (read-only arrays) for a sampler run again and again on the same grid (the segments of a
    multiple-shooting fit).
    """

    def __init__(self, sig: InputSignal, dt: float, n_steps: int, memo: bool = False) -> None:
        if sig.kind not in KINDS:
            raise EmaError(f"unknown input kind '{sig.kind}'; expected one of {KINDS}")
        self.signal = sig
        self.dt = float(dt)
        self.n_steps = int(n_steps)
        self.duration = self.n_steps * self.dt
        self._table = _profile(sig) if sig.kind == "csv" else None
        self._load = None
        if sig.load_table is not None:
            self._load = (np.asarray(sig.load_table[0]), np.asarray(sig.load_table[1]))
        self._load_sine = sig.load_sine
        self._ext = None
        if sig.ext_table is not None:
            self._ext = (np.asarray(sig.ext_table[0], dtype=np.float64),
                         np.asarray(sig.ext_table[1], dtype=np.float64))
        # np.gradient (the CSV velocity) takes its formula from the whole grid
        self._uniform = _uniform_grid(self.dt, self.n_steps) if sig.kind == "csv" else True
        is_step = sig.kind == "step" and sig.amplitude != 0.0
        self.step_info = np.array([1.0 if is_step else 0.0, sig.amplitude, sig.start],
                                  dtype=np.float64)
        self._memo: dict[tuple[int, int], Any] | None = {} if memo else None

    @property
    def has_load(self) -> bool:
        return self._load is not None or self._load_sine is not None

    @property
    def has_ext(self) -> bool:
        return self._ext is not None

    @property
    def ext_hold(self) -> bool:
        """Whether the input signal is held between its samples (else interpolated)."""
        return self.signal.ext_hold

    def ext_chunk(self, k0: int, k1: int) -> np.ndarray | None:
        """The input signal at the half steps of steps ``k0 <= k < k1`` (as :meth:`chunk`), or
        None without one."""
        if self._ext is None:
            return None
        n, dt = self.n_steps, self.dt
        th = np.arange(2 * k0, min(2 * k1, 2 * n) + 1) * (0.5 * dt)
        return np.ascontiguousarray(sample_table(*self._ext, th, self.signal.ext_hold))

    def chunk(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The inputs of steps ``k0 <= k < k1`` (``0 <= k0 < k1 <= n_steps + 1``) ->
        (position at the half steps ``j = 2*k0 .. min(2*k1, 2*n_steps)`` [rad], velocity at the
        steps [rad/s], load torque at the half steps [N*m] or None)."""
        if self._memo is None:
            return self._sample(k0, k1)
        key = (k0, k1)
        if key not in self._memo:
            out = self._sample(k0, k1)
            for a in out:
                if a is not None:
                    a.flags.writeable = False
            self._memo[key] = out
        return self._memo[key]

    def _sample(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        n, dt = self.n_steps, self.dt
        th = np.arange(2 * k0, min(2 * k1, 2 * n) + 1) * (0.5 * dt)
        pos = np.ascontiguousarray(_position(self.signal, th, self.duration, self._table),
                                   dtype=np.float64)
        if self.signal.kind == "csv":
            vel = self._csv_velocity(k0, k1)
        else:
            t = np.arange(k0, k1) * dt
            vel = np.ascontiguousarray(_velocity(self.signal, t, self.duration),
                                       dtype=np.float64)
        load = None
        if self.has_load:
            load = np.zeros_like(th)
            if self._load is not None:
                load += np.interp(th, *self._load)
            if self._load_sine is not None:
                amp, freq = self._load_sine
                load += amp * np.sin(2.0 * math.pi * freq * th)
        return pos, vel, load

    def _csv_velocity(self, k0: int, k1: int) -> np.ndarray:
        """``np.gradient(pos, t)`` over the whole grid (second-order central differences inside,
        one-sided at both ends), evaluated for steps k0..k1-1 only, with numpy's formulas."""
        n, dt = self.n_steps, self.dt
        lo, hi = max(k0 - 1, 0), min(k1, n)  # the steps whose positions enter
        t = np.arange(lo, hi + 1) * dt
        f = np.interp(t, *self._table)
        out = np.empty(k1 - k0)
        a, b = max(k0, 1), min(k1, n)  # interior steps a..b-1
        i = np.arange(a, b) - lo  # their index in t and f
        if b > a:
            if self._uniform:
                out[a - k0:b - k0] = (f[i + 1] - f[i - 1]) / (2. * dt)
            else:
                dx1 = t[i] - t[i - 1]
                dx2 = t[i + 1] - t[i]
                ca = -(dx2) / (dx1 * (dx1 + dx2))
                cb = (dx2 - dx1) / (dx1 * dx2)
                cc = dx1 / (dx2 * (dx1 + dx2))
                out[a - k0:b - k0] = ca * f[i - 1] + cb * f[i] + cc * f[i + 1]
        if k0 == 0:
            out[0] = (f[1] - f[0]) / (dt if self._uniform else t[1] - t[0])
        if k1 == n + 1:
            out[-1] = (f[-1] - f[-2]) / (dt if self._uniform else t[-1] - t[-2])
        return out

    def max_abs_position(self) -> float:
        """max |reference| over every half step of the run [rad], block by block."""
        peak = 0.0
        for k0 in range(0, self.n_steps + 1, SCAN_STEPS):
            pos, _, _ = self.chunk(k0, min(k0 + SCAN_STEPS, self.n_steps + 1))
            peak = max(peak, float(np.max(np.abs(pos))))
        return peak


class _Presampled:
    """A :class:`Reference` (sampled for the whole run) behind the :class:`Sampler` interface."""

    def __init__(self, ref: Reference, n_steps: int) -> None:
        if ref.pos_half.shape != (2 * n_steps + 1,) or ref.vel.shape != (n_steps + 1,):
            raise ValueError("references were sampled for a different number of steps")
        self.ref = ref
        self.n_steps = n_steps
        self.step_info = ref.step_info
        self.has_load = ref.load_half is not None
        self.has_ext = ref.ext_half is not None
        self.ext_hold = ref.ext_hold

    def ext_chunk(self, k0: int, k1: int) -> np.ndarray | None:
        ext = self.ref.ext_half
        return None if ext is None else ext[2 * k0:min(2 * k1, 2 * self.n_steps) + 1]

    def chunk(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        j1 = min(2 * k1, 2 * self.n_steps) + 1
        load = self.ref.load_half
        return (self.ref.pos_half[2 * k0:j1], self.ref.vel[k0:k1],
                None if load is None else load[2 * k0:j1])


def sampler(source: InputSignal | Reference | Sampler, dt: float,
            n_steps: int) -> Sampler | _Presampled:
    """``source`` ready to be sampled in chunks on the grid of ``n_steps`` steps of ``dt``."""
    if isinstance(source, Sampler):
        if source.n_steps != n_steps or source.dt != dt:
            raise ValueError("a Sampler prepared for another time grid")
        return source
    if isinstance(source, Reference):
        return _Presampled(source, n_steps)
    return Sampler(source, dt, n_steps)


def sample(sig: InputSignal, dt: float, n_steps: int) -> Reference:
    """Sample ``sig`` on the kernel's grid for the whole run at once (half steps for position,
    full steps for velocity). The kernel itself samples in time chunks (:func:`sampler`)."""
    s = Sampler(sig, dt, n_steps)
    pos, vel, load = s.chunk(0, n_steps + 1)
    return Reference(pos, vel, s.step_info, load, s.ext_chunk(0, n_steps + 1), sig.ext_hold)


HOLD_TOL = 1e-3  # a table instant this close (fraction of its median spacing) to a time is on it


def sample_table(t: np.ndarray, v: np.ndarray, times: np.ndarray, hold: bool) -> np.ndarray:
    """A table ``(t, v)`` at ``times``: held from each of its instants to the next (zero-order
    hold; an instant within :data:`HOLD_TOL` of its spacing before a time counts as reached:
    logged time stamps jitter) or interpolated linearly; its end values held outside it."""
    if not hold or t.shape[0] < 2:
        return np.interp(times, t, v)
    tol = HOLD_TOL * float(np.median(np.diff(t)))
    i = np.searchsorted(t, times + tol, side="right") - 1
    return v[np.clip(i, 0, t.shape[0] - 1)]

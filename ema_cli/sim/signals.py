"""Position reference signals (step, ramp, sine, chirp, CSV profile) sampled for the RK4 kernel.

A reference is sampled at every half step (``t = j*dt/2``, ``j = 0..2*n_steps``) so the RK4
stages see it exactly; its velocity (for the velocity-error metrics) at every full step.
All values SI (rad, rad/s, s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.units import DEG

KINDS = ("step", "ramp", "sine", "chirp", "csv")


@dataclass(frozen=True)
class InputSignal:
    """A reference signal in SI units.

    kind      step | ramp | sine | chirp | csv
    amplitude step size / sine and chirp amplitude [rad]
    start     time the signal starts [s] (before it: 0)
    rate      ramp slope [rad/s]; the ramp stops at ``amplitude`` if that is > 0
    freq      sine frequency [Hz]; chirp start frequency
    freq_end  chirp end frequency [Hz] (linear sweep over ``sweep_time``)
    sweep_time chirp sweep duration [s] (0: the run's duration)
    offset    constant added to sine/chirp [rad]
    path      CSV file with columns t_s, theta_ref_deg (csv kind)
    load_table external load-torque profile ((t [s], ...), (torque [N*m], ...)), linearly
              interpolated, its end values held outside it; None: no profile
    load_path  the CSV the profile came from (for reports)

    The signal carries every time-varying input of a run: the position reference and, when
    given, the load-torque profile (``plant.load_torque_nb``).
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

    def describe(self) -> str:
        """A short human description in the paper's units."""
        a = self.amplitude / DEG
        if self.kind == "step":
            return f"{a:g} deg step at t = {self.start:g} s"
        if self.kind == "ramp":
            return f"ramp {self.rate / DEG:g} deg/s from t = {self.start:g} s"
        if self.kind == "sine":
            return f"sine {a:g} deg, {self.freq:g} Hz"
        if self.kind == "chirp":
            return f"chirp {a:g} deg, {self.freq:g} -> {self.freq_end:g} Hz"
        return f"profile {self.path}"


def load_profile(path: str | Path, value: str = "theta_ref_deg",
                 scale: float = DEG) -> tuple[np.ndarray, np.ndarray]:
    """Read a CSV profile (columns ``t_s`` and ``value``) -> (t [s], value*scale), validated.

    The reference profile has ``theta_ref_deg`` (returned in rad); the load-torque profile
    ``torque_nm`` (``scale`` 1).
    """
    import pandas as pd

    p = Path(path)
    if not p.is_file():
        raise EmaError(f"profile '{p}' does not exist")
    try:
        df = pd.read_csv(p)
    except Exception as exc:  # pandas raises many types for malformed files
        raise EmaError(f"profile '{p}' is not a readable CSV: {exc}") from None
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


def _position(sig: InputSignal, t: np.ndarray, duration: float) -> np.ndarray:
    tau = t - sig.start
    on = tau >= 0.0
    if sig.kind == "step":
        return np.where(on, sig.amplitude, 0.0)
    if sig.kind == "ramp":
        y = np.where(on, sig.rate * tau, 0.0)
        if sig.amplitude > 0:
            y = np.clip(y, -sig.amplitude, sig.amplitude)
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
        if sig.table is None:
            tt, yy = load_profile(sig.path or "")
        else:
            tt, yy = np.asarray(sig.table[0]), np.asarray(sig.table[1])
        return np.interp(t, tt, yy)
    raise EmaError(f"unknown input kind '{sig.kind}'; expected one of {KINDS}")


def _velocity(sig: InputSignal, t: np.ndarray, pos: np.ndarray, duration: float) -> np.ndarray:
    tau = t - sig.start
    on = tau >= 0.0
    if sig.kind == "step":
        return np.zeros_like(t)
    if sig.kind == "ramp":
        moving = on & ((sig.amplitude <= 0) | (np.abs(sig.rate * tau) < sig.amplitude))
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
    return np.gradient(pos, t)  # csv: finite differences of the interpolated profile


@dataclass(frozen=True)
class Reference:
    """A sampled reference for the kernel.

    pos_half[2*n_steps+1]  position at t = j*dt/2 [rad]
    vel[n_steps+1]         velocity at t = k*dt [rad/s]
    step_info[3]           (is_step, final value [rad], step time [s]) for the step metrics
    load_half[2*n_steps+1] external load-torque profile at t = j*dt/2 [N*m], or None (none)
    """

    pos_half: np.ndarray
    vel: np.ndarray
    step_info: np.ndarray
    load_half: np.ndarray | None = None


def sample(sig: InputSignal, dt: float, n_steps: int) -> Reference:
    """Sample ``sig`` on the kernel's grid (half steps for position, full steps for velocity)."""
    duration = n_steps * dt
    th = np.arange(2 * n_steps + 1) * (0.5 * dt)
    pos_half = np.ascontiguousarray(_position(sig, th, duration), dtype=np.float64)
    t = np.arange(n_steps + 1) * dt
    vel = np.ascontiguousarray(_velocity(sig, t, pos_half[::2], duration), dtype=np.float64)
    is_step = sig.kind == "step" and sig.amplitude != 0.0
    info = np.array([1.0 if is_step else 0.0, sig.amplitude, sig.start], dtype=np.float64)
    load = None
    if sig.load_table is not None:
        load = np.ascontiguousarray(
            np.interp(th, np.asarray(sig.load_table[0]), np.asarray(sig.load_table[1])),
            dtype=np.float64)
    return Reference(pos_half, vel, info, load)

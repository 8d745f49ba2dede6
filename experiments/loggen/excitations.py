"""Position commands theta_ref(t) [rad] as smooth analytic functions of time [s].

The generator integrates with the analytic command (``value``, a scalar, called by the
right-hand side); a log records it only at its samples (``sample``, vectorised). Each command
starts at 0 (the actuator starts at rest at 0) and describes itself (``describe``) for the
sidecar and the manifest.

- ``Chirp``: ``A*sin(2*pi*(f0*t + (f1 - f0)/(2*T)*t^2))`` for t <= T, then the f1 sine
  (ema's ``--make-data`` chirp: 5 deg, 0.5 -> 8 Hz over 4 s).
- ``Multisine``: ``w(t)*sum_k a_k*sin(2*pi*f_k*t + phi_k)``, frequencies log-spaced over
  0.3-10 Hz with a random jitter, random phases, a_k ~ f_k^-1/2 with sum a_k = the peak bound;
  w(t) a raised-cosine fade-in over ``FADE_S`` so theta_ref and its rate start at 0.
- ``Steps``: a sequence of levels (uniform within +-5 deg) held 0.3-0.8 s, each transition a
  quintic smoothstep (C2: position, rate and acceleration continuous) of 20-50 ms; the first
  hold at 0 lasts ``FIRST_HOLD_S``.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from experiments.loggen.params import DEG

FADE_S = 0.25  # multisine fade-in duration [s]
MULTISINE_BAND_HZ = (0.3, 10.0)  # multisine frequency band [Hz]
MULTISINE_N = 6  # multisine components [-]
MULTISINE_PEAK_DEG = 5.0  # multisine bound on |theta_ref|, sum of the amplitudes [deg]
STEP_LEVEL_DEG = 5.0  # steps: levels uniform within +-this [deg]
STEP_HOLD_S = (0.3, 0.8)  # steps: hold durations [s]
STEP_RAMP_S = (0.02, 0.05)  # steps: transition durations [s]
FIRST_HOLD_S = 0.2  # steps: rest at 0 before the first transition [s]
KINDS = ("chirp", "multisine", "steps")


@dataclass(frozen=True)
class Chirp:
    """Linear chirp: amplitude [rad], f0 -> f1 [Hz] over sweep_s [s], then f1."""

    amplitude: float = 5.0 * DEG
    f0: float = 0.5
    f1: float = 8.0
    sweep_s: float = 4.0

    def value(self, t: float) -> float:
        """theta_ref(t) [rad] at one time t [s]."""
        if t <= 0.0:
            return 0.0
        T = self.sweep_s
        if t <= T:
            ph = self.f0 * t + 0.5 * (self.f1 - self.f0) / T * t * t
        else:
            ph = self.f0 * T + 0.5 * (self.f1 - self.f0) * T + self.f1 * (t - T)
        return self.amplitude * math.sin(2.0 * math.pi * ph)

    def sample(self, t: np.ndarray) -> np.ndarray:
        """theta_ref at the times t [s] -> [rad]."""
        return np.array([self.value(float(x)) for x in np.asarray(t, dtype=float)])

    def describe(self) -> dict:
        return {"kind": "chirp", "amplitude_deg": self.amplitude / DEG, "f0_hz": self.f0,
                "f1_hz": self.f1, "sweep_s": self.sweep_s}


@dataclass(frozen=True)
class Multisine:
    """Faded-in sum of sines: amplitudes [rad], frequencies [Hz], phases [rad]."""

    amplitudes: tuple[float, ...]
    freqs: tuple[float, ...]
    phases: tuple[float, ...]
    fade_s: float = FADE_S

    @classmethod
    def random(cls, rng: np.random.Generator) -> Multisine:
        """Log-spaced frequencies over :data:`MULTISINE_BAND_HZ` jittered by up to +-10 %
        (kept in the band), uniform phases, a_k ~ f_k^-1/2 summing to the peak bound."""
        lo, hi = MULTISINE_BAND_HZ
        f = np.geomspace(lo, hi, MULTISINE_N) * np.exp(rng.uniform(-0.1, 0.1, MULTISINE_N))
        f = np.clip(f, lo, hi)
        ph = rng.uniform(0.0, 2.0 * math.pi, MULTISINE_N)
        a = f**-0.5
        a = a / a.sum() * MULTISINE_PEAK_DEG * DEG
        return cls(tuple(map(float, a)), tuple(map(float, f)), tuple(map(float, ph)))

    def value(self, t: float) -> float:
        if t <= 0.0:
            return 0.0
        s = 0.0
        for a, f, ph in zip(self.amplitudes, self.freqs, self.phases, strict=True):
            s += a * math.sin(2.0 * math.pi * f * t + ph)
        if t < self.fade_s:
            s *= 0.5 * (1.0 - math.cos(math.pi * t / self.fade_s))
        return s

    def sample(self, t: np.ndarray) -> np.ndarray:
        return np.array([self.value(float(x)) for x in np.asarray(t, dtype=float)])

    def describe(self) -> dict:
        return {"kind": "multisine", "amplitudes_deg": [a / DEG for a in self.amplitudes],
                "freqs_hz": list(self.freqs), "phases_rad": list(self.phases),
                "fade_in_s": self.fade_s,
                "formula": "w(t)*sum a_k*sin(2 pi f_k t + phi_k), w = raised-cosine "
                           "fade-in"}


def smoothstep5(u: float) -> float:
    """Quintic smoothstep on [0, 1]: 0 -> 1 with zero rate and acceleration at both ends."""
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10.0 + u * (-15.0 + 6.0 * u))


@dataclass(frozen=True)
class Steps:
    """Smoothed steps: transition k starts at starts[k] [s], lasts ramps[k] [s] and goes from
    levels[k] to levels[k+1] [rad]; levels[0] = 0."""

    starts: tuple[float, ...]
    ramps: tuple[float, ...]
    levels: tuple[float, ...]

    @classmethod
    def random(cls, rng: np.random.Generator, duration_s: float) -> Steps:
        starts, ramps, levels = [], [], [0.0]
        t = FIRST_HOLD_S
        while t < duration_s:
            r = float(rng.uniform(*STEP_RAMP_S))
            starts.append(t)
            ramps.append(r)
            levels.append(float(rng.uniform(-STEP_LEVEL_DEG, STEP_LEVEL_DEG)) * DEG)
            t += r + float(rng.uniform(*STEP_HOLD_S))
        return cls(tuple(starts), tuple(ramps), tuple(levels))

    def value(self, t: float) -> float:
        k = bisect.bisect_right(self.starts, t) - 1
        if k < 0:
            return self.levels[0]
        a, b = self.levels[k], self.levels[k + 1]
        return a + (b - a) * smoothstep5((t - self.starts[k]) / self.ramps[k])

    def sample(self, t: np.ndarray) -> np.ndarray:
        return np.array([self.value(float(x)) for x in np.asarray(t, dtype=float)])

    def describe(self) -> dict:
        return {"kind": "steps", "starts_s": list(self.starts), "ramps_s": list(self.ramps),
                "levels_deg": [v / DEG for v in self.levels],
                "transition": "quintic smoothstep 10u^3 - 15u^4 + 6u^5"}


Command = Chirp | Multisine | Steps


def make_command(kind: str, rng: np.random.Generator, duration_s: float) -> Command:
    """The command ``kind`` (one of :data:`KINDS`), drawing its random parts from ``rng``."""
    if kind == "chirp":
        return Chirp(sweep_s=duration_s)
    if kind == "multisine":
        return Multisine.random(rng)
    if kind == "steps":
        return Steps.random(rng, duration_s)
    raise ValueError(f"unknown excitation '{kind}'; expected one of {KINDS}")

"""Synthetic identification data on demand: a closed-loop test log and a friction sweep from the
model with stated truths (``ema identify --make-data``). Compute only: tables and truths are
returned; ``report.closed_loop_report`` writes them.

Closed-loop log: a chirp position command (5 deg, 0.5 -> 8 Hz over 4 s by default); the
simulator follows the chirp itself at ``dt_s`` and records the load angle, motor speed, current
and voltage demand at the sample instants (every ``sample_interval_s``), each with Gaussian
noise of ``noise_pct`` % of its RMS; the log keeps the command at its samples only (noise-free),
as a real log does (a fit passes a cubic spline through them by default, ``command``).

Friction sweep: the model's steady-state friction (``model.lugre.steady_friction_nb``, which
the LuGre model reaches at constant speed) at log-spaced motor speeds in both directions, with
Gaussian noise of ``noise_pct`` % of the torque RMS.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.units import DEG, RPM

NOISE_TAG = 0x6C6F6773  # second entropy word of the noise streams of synthetic logs
MAKE_DATA_PLANT = {"alpha": 0.003, "friction": 1.0, "sigma2": 1.0e-4}
"""Truths of synthetic data beyond the model defaults (kL 590 N*m/rad, Fc 0.02 N*m, Fs 1.5*Fc,
vs 1 rad/s, sigma0 1e3*Fc): half backlash 3 mrad, LuGre friction on, viscous 1e-4 N*m*s/rad."""
LOG_CHANNELS = ("theta_load_deg", "omega_motor_rpm", "current_a", "voltage_cmd_v")
"""The measured channels a closed-loop log may carry (edge columns of ``ema simulate``)."""
TRUTH_NAMES = ("kL", "alpha", "zeta_t", "c", "contact_tau", "contact_hc", "Fc", "Fs", "vs",
               "delta", "sigma0", "sigma1", "sigma2", "Jm", "JL", "bL")
"""The parameters whose truths a synthetic log states."""


@dataclass(frozen=True)
class SyntheticLog:
    """A synthetic data table (edge-unit columns), the full SI truths and a description."""

    kind: str
    columns: dict[str, np.ndarray]
    truth: dict[str, float]
    params: dict[str, float]
    noise_pct: float
    noise_std: dict[str, float]
    description: str

    def sidecar(self) -> dict[str, Any]:
        """The content of the ``<stem>.truth.json`` sidecar."""
        return {"kind": self.kind, "description": self.description,
                "truth": self.truth, "units": "SI (as `ema params`)",
                "noise_pct_of_rms": self.noise_pct, "noise_std_edge_units": self.noise_std,
                "all_parameters": self.params}


def _rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, NOISE_TAG]))


def resolve_truth(plant: Mapping[str, Any]) -> dict[str, float]:
    """The SI parameters of synthetic data: model defaults, :data:`MAKE_DATA_PLANT`, ``plant``."""
    from ema_cli.model.params import resolve

    return resolve({**MAKE_DATA_PLANT, **dict(plant)})


def closed_loop_log(
    plant: Mapping[str, Any], noise_pct: float, seed: int, *, amplitude_deg: float = 5.0,
    freq_hz: float = 0.5, freq_end_hz: float = 8.0, duration_s: float = 4.0,
    sample_interval_s: float = 1e-3, dt_s: float = 1e-5,
) -> SyntheticLog:
    """A closed-loop test log from the model (see the module docstring)."""
    from ema_cli.sim.grid import plan_steps
    from ema_cli.sim.runner import simulate
    from ema_cli.sim.signals import InputSignal, sample

    params = resolve_truth(plant)
    n_s, _ = plan_steps(duration_s, sample_interval_s, sample_interval_s)
    chirp = InputSignal("chirp", amplitude=amplitude_deg * DEG, freq=freq_hz,
                        freq_end=freq_end_hz, sweep_time=duration_s)
    t = np.arange(n_s + 1) * sample_interval_s
    theta_ref = sample(chirp, sample_interval_s, n_s).pos_half[::2]
    res = simulate(params, chirp, duration=float(t[-1]), dt=dt_s,
                   output_interval=sample_interval_s)
    if bool(res.diverged[0]):
        raise EmaError("the simulation that generates the closed-loop log diverged; check the "
                       "--set plant values", 1)
    rng = _rng(seed)
    cols: dict[str, np.ndarray] = {"t_s": t, "theta_ref_deg": theta_ref / DEG}
    stds = {}
    for name in LOG_CHANNELS:
        y = res.signal(name, edge=True)
        std = noise_pct / 100.0 * float(np.sqrt(np.mean(y**2)))
        cols[name] = y + std * rng.standard_normal(y.shape[0])
        stds[name] = std
    desc = (f"synthetic closed-loop log: chirp {amplitude_deg:g} deg, {freq_hz:g} -> "
            f"{freq_end_hz:g} Hz over {duration_s:g} s, sampled every {sample_interval_s:g} s, "
            f"simulated at dt = {dt_s:g} s; noise {noise_pct:g} % of each channel's RMS, "
            f"seed {seed}")
    truth = {n: params[n] for n in TRUTH_NAMES}
    return SyntheticLog("closed-loop", cols, truth, params, float(noise_pct), stds, desc)


SWEEP_RPM = (1.0, 1000.0, 20)  # default sweep: 20 log-spaced speeds per direction [rpm]


def friction_sweep_log(plant: Mapping[str, Any], noise_pct: float, seed: int, *,
                       speeds_rpm: tuple[float, float, int] = SWEEP_RPM) -> SyntheticLog:
    """A friction sweep from the model's static curve (see the module docstring)."""
    from ema_cli.identify.friction.sweep import static_curve

    params = resolve_truth(plant)
    lo, hi, n = speeds_rpm
    sp = np.geomspace(lo, hi, int(n))
    rpm = np.concatenate([-sp[::-1], sp])
    T = static_curve(rpm * RPM, params["Fc"], params["Fs"], params["vs"], params["sigma2"],
                     params["delta"])
    std = noise_pct / 100.0 * float(np.sqrt(np.mean(T**2)))
    noisy = T + std * _rng(seed).standard_normal(T.shape[0])
    desc = (f"synthetic friction sweep: {2 * int(n)} constant motor speeds, +-{lo:g} .. "
            f"{hi:g} rpm (log-spaced), the model's steady-state LuGre friction; noise "
            f"{noise_pct:g} % of the torque RMS, seed {seed}")
    truth = {k: params[k] for k in ("Fc", "Fs", "vs", "delta", "sigma2")}
    return SyntheticLog("friction-sweep", {"omega_rpm": rpm, "torque_nm": noisy}, truth,
                        params, float(noise_pct), {"torque_nm": std}, desc)

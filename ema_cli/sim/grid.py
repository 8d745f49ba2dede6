"""The time grid of a run, without the compiled kernel: step counts, decimation, sample times.

Kept apart from ``sim.runner`` so that validating a config (``ema validate``) never imports
numba or pandas. Everything here is SI (seconds).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.model.params import equivalent_inertia

DEFAULT_DT = 1e-5  # integration step [s] (docs/model.md §6)
DEFAULT_OUTPUT_INTERVAL = 1e-4  # recorded-signal interval [s]
RESOLUTION_LIMIT = 0.3  # warn when dt * (fastest rate) exceeds this [-] (RK4 stability ~2.8)
MAX_STEPS = 2_000_000_000  # refuse absurd step counts


def plan_steps(duration: float, dt: float, output_interval: float | None) -> tuple[int, int]:
    """Validate the time grid -> (n_steps, decimation). ``output_interval`` None: no recording."""
    if not (math.isfinite(dt) and dt > 0):
        raise EmaError(f"dt must be a positive number of seconds, got {dt}")
    if not (math.isfinite(duration) and duration > 0):
        raise EmaError(f"duration must be a positive number of seconds, got {duration}")
    if dt > duration:
        raise EmaError(f"dt ({dt} s) must not exceed the duration ({duration} s)")
    ratio = duration / dt
    if not math.isfinite(ratio) or ratio > MAX_STEPS:
        raise EmaError(f"duration / dt = {ratio:.3g} steps is too many; at most {MAX_STEPS:,}")
    n_steps = round(ratio)
    if abs(n_steps * dt - duration) > 1e-9 * duration:
        raise EmaError(f"the duration ({duration} s) must be a whole number of steps dt = {dt} s")
    if n_steps > MAX_STEPS:
        raise EmaError(f"{n_steps} steps is too many (duration / dt); at most {MAX_STEPS}")
    if output_interval is None:
        return n_steps, 0
    if not (math.isfinite(output_interval) and output_interval > 0):
        raise EmaError(
            f"output interval must be a positive number of seconds, got {output_interval}")
    if output_interval > duration:
        raise EmaError(f"the output interval ({output_interval:g} s) must not exceed the "
                       f"duration ({duration:g} s)")
    dec = round(output_interval / dt)
    if dec < 1 or abs(dec * dt - output_interval) > 1e-9 * output_interval:
        raise EmaError(
            f"the output interval ({output_interval} s) must be a whole multiple of dt ({dt} s)"
        )
    return n_steps, dec


def resolution_warnings(params: Mapping[str, float], dt: float) -> list[str]:
    """Warnings for dynamics that look under-resolved by the fixed step ``dt`` [s]."""
    rates: dict[str, float] = {}
    amp = params.get("drive", 0.0) == 1.0
    if not amp:
        rates["electrical pole R/L"] = params["R"] / params["L"]
    elif params.get("amp_tau", 0.0) > 0:
        rates["amplifier bandwidth 1/tau"] = 1.0 / params["amp_tau"]
    m2 = params["m"] ** 2
    if params.get("rigid", 0.0) == 1.0:
        jtot = params["JL"] + m2 * params["Jm"]
        visc = (params["bL"] + m2 * params["bm"] + params.get("Fv_L", 0.0)
                + (m2 * params["sigma2"] if params["friction"] else 0.0))
        rates["viscous time constant of the axis"] = visc / jtot
    else:
        jeq = equivalent_inertia(params)
        rates["transmission mode sqrt(kL/Jeq)"] = math.sqrt(params["kL"] / jeq)
        rates["transmission damping c/Jeq"] = params["c"] / jeq
        if params["friction"]:
            rates["viscous friction sigma2/Jm"] = params["sigma2"] / params["Jm"]
        if params.get("friction_L", 0.0):
            rates["load viscous friction Fv_L/JL"] = params["Fv_L"] / params["JL"]
    out = []
    for what, rate in rates.items():
        if rate * dt > RESOLUTION_LIMIT:
            out.append(
                f"dt = {dt:g} s may under-resolve the {what} ({rate:.3g} 1/s, "
                f"rate*dt = {rate * dt:.3g} > {RESOLUTION_LIMIT}); try dt <= "
                f"{RESOLUTION_LIMIT / rate / 2:.2g} s"
            )
    return out


def off_grid(ts: np.ndarray | float, dt: float) -> np.ndarray:
    """True where a controller sample time ``ts`` [s] > 0 is not a whole multiple of ``dt``
    (0 is the continuous controller and always fine)."""
    ts = np.asarray(ts, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        n = ts / dt
        return (ts > 0) & ((n < 1 - 1e-9) | ~np.isfinite(n)
                           | (np.abs(n - np.round(n)) > 1e-9 * np.maximum(n, 1.0)))

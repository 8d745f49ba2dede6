"""Python side of the simulator: validate, allocate, call the kernel, wrap the result.

``simulate_batch`` runs a parameter matrix ``P[n_cases, N_PARAMS]`` against one or more sampled
references in one kernel call; ``simulate`` is the one-configuration convenience. Results are SI;
``BatchResult.metrics_frame`` / ``signals_frame`` give tables in edge units (deg, rpm, ...).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ema_cli._numba import CACHE_KEY as KERNEL_KEY
from ema_cli.errors import EmaError
from ema_cli.model.params import INDEX, N_PARAMS, equivalent_inertia, to_row
from ema_cli.sim.kernel import KERNELS, LANES
from ema_cli.sim.signals import InputSignal, Reference, sample
from ema_cli.sim.tables import METRICS, N_METRICS, N_SIGNALS, SIGNALS

__all__ = ["KERNEL_KEY", "BatchResult", "simulate", "simulate_batch"]

DEFAULT_DT = 1e-5  # integration step [s] (docs/model.md §6)
DEFAULT_OUTPUT_INTERVAL = 1e-4  # recorded-signal interval [s]
RESOLUTION_LIMIT = 0.3  # warn when dt * (fastest rate) exceeds this [-] (RK4 stability ~2.8)
MAX_STEPS = 2_000_000_000  # refuse absurd step counts
LANE_MIN_CASES = 4  # per thread: below this many cases, the one-lane path is faster [cases]


def plan_steps(duration: float, dt: float, output_interval: float | None) -> tuple[int, int]:
    """Validate the time grid -> (n_steps, decimation). ``output_interval`` None: no recording."""
    if not (math.isfinite(dt) and dt > 0):
        raise EmaError(f"dt must be a positive number of seconds, got {dt}")
    if not (math.isfinite(duration) and duration > 0):
        raise EmaError(f"duration must be a positive number of seconds, got {duration}")
    if dt > duration:
        raise EmaError(f"dt ({dt} s) must not exceed the duration ({duration} s)")
    n_steps = round(duration / dt)
    if abs(n_steps * dt - duration) > 1e-9 * duration:
        raise EmaError(f"the duration ({duration} s) must be a whole number of steps dt = {dt} s")
    if n_steps > MAX_STEPS:
        raise EmaError(f"{n_steps} steps is too many (duration / dt); at most {MAX_STEPS}")
    if output_interval is None:
        return n_steps, 0
    if not (math.isfinite(output_interval) and output_interval > 0):
        raise EmaError(
            f"output interval must be a positive number of seconds, got {output_interval}")
    dec = round(output_interval / dt)
    if dec < 1 or abs(dec * dt - output_interval) > 1e-9 * output_interval:
        raise EmaError(
            f"the output interval ({output_interval} s) must be a whole multiple of dt ({dt} s)"
        )
    return n_steps, dec


def resolution_warnings(params: Mapping[str, float], dt: float) -> list[str]:
    """Warnings for dynamics that look under-resolved by the fixed step ``dt`` [s]."""
    rates = {"electrical pole R/L": params["R"] / params["L"]}
    jeq = equivalent_inertia(params)
    rates["transmission mode sqrt(kL/Jeq)"] = math.sqrt(params["kL"] / jeq)
    rates["transmission damping c/Jeq"] = params["c"] / jeq
    if params["friction"]:
        rates["viscous friction sigma2/Jm"] = params["sigma2"] / params["Jm"]
    out = []
    for what, rate in rates.items():
        if rate * dt > RESOLUTION_LIMIT:
            out.append(
                f"dt = {dt:g} s may under-resolve the {what} ({rate:.3g} 1/s, "
                f"rate*dt = {rate * dt:.2f} > {RESOLUTION_LIMIT}); try dt <= "
                f"{RESOLUTION_LIMIT / rate / 2:.2g} s"
            )
    return out


@dataclass
class BatchResult:
    """The output of one kernel call.

    P[n_cases, N_PARAMS]                 the SI parameter matrix that was run
    metrics[n_cases, N_METRICS]          SI metrics (columns: ``tables.METRICS``)
    signals[n_cases, n_out, N_SIGNALS]   SI signals every ``dec`` steps, or None
    t_out[n_out]                         the recorded times [s]
    """

    P: np.ndarray
    metrics: np.ndarray
    signals: np.ndarray | None
    t_out: np.ndarray
    dt: float
    n_steps: int
    dec: int

    @property
    def diverged(self) -> np.ndarray:
        """Boolean flag per case."""
        return self.metrics[:, [c.name for c in METRICS].index("diverged")] == 1.0

    def metrics_frame(self) -> pd.DataFrame:
        """Metrics in edge units, one row per case, units in the column names."""
        data = {c.edge: self.metrics[:, j] * c.factor for j, c in enumerate(METRICS)}
        df = pd.DataFrame(data)
        df["diverged"] = df["diverged"].astype(bool)
        return df

    def signals_frame(self, case: int = 0) -> pd.DataFrame:
        """Recorded signals of one case in edge units, ``t_s`` first."""
        if self.signals is None:
            raise ValueError("signals were not recorded (output interval None)")
        data = {"t_s": self.t_out}
        for j, c in enumerate(SIGNALS):
            data[c.edge] = self.signals[case, :, j] * c.factor
        return pd.DataFrame(data)


def lanes_for(n_cases: int, threads: int) -> int:
    """1 (every configuration alone, the fastest for a few) or :data:`kernel.LANES` (chunks
    advanced together in SIMD lanes), whichever is faster for ``n_cases`` on ``threads``."""
    return 1 if n_cases < LANE_MIN_CASES * max(threads, 1) else LANES


def off_grid(ts: np.ndarray | float, dt: float) -> np.ndarray:
    """True where a controller sample time ``ts`` [s] > 0 is not a whole multiple of ``dt``
    (0 is the continuous controller and always fine)."""
    ts = np.asarray(ts, dtype=np.float64)
    n = ts / dt
    return (ts > 0) & ((n < 1 - 1e-9) | (np.abs(n - np.round(n)) > 1e-9 * np.maximum(n, 1.0)))


def check_sample_times(P: np.ndarray, dt: float) -> None:
    """Every controller sample time in ``P`` must be 0 (continuous) or a whole multiple of dt."""
    ts = P[:, INDEX["Ts"]]
    bad = off_grid(ts, dt)
    if np.any(bad):
        raise EmaError(f"controller sample time {float(ts[bad][0]):g} s must be a whole multiple "
                       f"of the integration step dt = {dt:g} s")


def simulate_batch(
    P: np.ndarray,
    refs: Sequence[Reference],
    ref_index: np.ndarray | None,
    dt: float,
    n_steps: int,
    dec: int = 0,
    parallel: bool = False,
    lanes: int | None = None,
) -> BatchResult:
    """Run every row of ``P`` (SI parameter matrix) for ``n_steps`` steps of ``dt`` seconds.

    ``refs`` are references sampled for this grid; row c uses ``refs[ref_index[c]]``
    (``ref_index`` None: all use ``refs[0]``). ``dec`` > 0 records signals every ``dec`` steps.
    ``parallel`` spreads the chunks over numba threads; ``lanes`` is 1 (each configuration alone)
    or :data:`kernel.LANES` (chunks in SIMD lanes), default :func:`lanes_for`. Results are
    bit-identical whatever ``parallel`` and ``lanes`` are.
    """
    import numba

    P = np.ascontiguousarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != N_PARAMS:
        raise ValueError(f"P must have shape (n_cases, {N_PARAMS}), got {P.shape}")
    check_sample_times(P, dt)
    n_cases = P.shape[0]
    if ref_index is None:
        ref_index = np.zeros(n_cases, dtype=np.int64)
    ref_index = np.ascontiguousarray(ref_index, dtype=np.int64)
    ref_pos = np.stack([r.pos_half for r in refs])
    ref_vel = np.stack([r.vel for r in refs])
    info = np.stack([r.step_info for r in refs])
    if any(r.load_half is not None for r in refs):
        load = np.stack([r.load_half if r.load_half is not None else np.zeros_like(r.pos_half)
                         for r in refs])
    else:
        load = np.zeros((len(refs), 1))
    if ref_pos.shape[1] != 2 * n_steps + 1:
        raise ValueError("references were sampled for a different number of steps")
    n_out = n_steps // dec + 1 if dec > 0 else 0
    sig = np.full((n_cases, n_out, N_SIGNALS), np.nan)
    met = np.empty((n_cases, N_METRICS))
    if lanes is None:
        lanes = lanes_for(n_cases, numba.get_num_threads() if parallel else 1)
    if lanes not in (1, LANES):
        raise ValueError(f"lanes must be 1 or {LANES}, got {lanes}")
    # group the rows that need the costlier kernel variants (friction; digital controller,
    # quantisers, locked motor) so that a chunk rarely mixes them; results are put back in order
    extra = ((P[:, INDEX["Ts"]] > 0) | (P[:, INDEX["q_pos"]] > 0) | (P[:, INDEX["q_speed"]] > 0)
             | (P[:, INDEX["locked"]] != 0))
    order = np.argsort(2 * (P[:, INDEX["friction"]] != 0) + extra, kind="stable")
    identity = bool(np.all(order == np.arange(n_cases)))
    Pk = P if identity else np.ascontiguousarray(P[order])
    qk = ref_index if identity else np.ascontiguousarray(ref_index[order])
    KERNELS[(bool(parallel), lanes > 1)](Pk, ref_pos, ref_vel, load, info, qk, dt, n_steps, dec,
                                         sig, met)
    if not identity:
        inverse = np.empty_like(order)
        inverse[order] = np.arange(n_cases)
        met = met[inverse]
        sig = sig[inverse]
    t_out = np.arange(n_out) * (dec * dt)
    return BatchResult(P, met, sig if dec > 0 else None, t_out, dt, n_steps, dec)


def simulate(
    params: Mapping[str, float],
    signal: InputSignal,
    duration: float,
    dt: float = DEFAULT_DT,
    output_interval: float | None = DEFAULT_OUTPUT_INTERVAL,
) -> BatchResult:
    """Simulate one resolved SI configuration (see ``model.params.resolve``)."""
    n_steps, dec = plan_steps(duration, dt, output_interval)
    ref = sample(signal, dt, n_steps)
    P = np.array([to_row(params)])
    return simulate_batch(P, [ref], None, dt, n_steps, dec)


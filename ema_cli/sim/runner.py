"""Python side of the simulator: validate, allocate, call the kernel, wrap the result.

``simulate_batch`` runs a parameter matrix ``P[n_cases, N_PARAMS]`` against one or more
references; ``simulate`` is the one-configuration convenience. Results are SI;
``BatchResult.metrics_frame`` / ``signals_frame`` give tables in edge units (deg, rpm, ...).

Memory is bounded by what is recorded, not by the duration: the kernel is called once per time
chunk of :data:`TIME_CHUNK` steps, each time with the references sampled for that chunk only,
and carries its state from call to call (``sim.kernel``, "Time chunks"); a chunked run is bit
for bit the run done in one call. The recorded signals are checked against a memory budget
(:func:`record_budget`) before anything is allocated.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

from ema_cli._numba import CACHE_KEY as KERNEL_KEY
from ema_cli.errors import EmaError
from ema_cli.model.params import INDEX, N_PARAMS, to_row
from ema_cli.sim.grid import (  # noqa: F401 (re-exported: the runner's grid API)
    DEFAULT_DT,
    DEFAULT_OUTPUT_INTERVAL,
    MAX_STEPS,
    RESOLUTION_LIMIT,
    off_grid,
    plan_steps,
    resolution_warnings,
)
from ema_cli.sim.kernel import (
    ALIVE_ROW,
    KERNELS,
    LANES,
    N_ROWS,
    one_lane_only,
    variant_codes,
    variant_keys,
    variant_order,
)
from ema_cli.sim.signals import InputSignal, Reference, Sampler, sampler
from ema_cli.sim.tables import METRICS, N_METRICS, N_SIGNALS, PAPER_SIGNALS, SIGNALS

__all__ = ["KERNEL_KEY", "BatchResult", "load_kernel", "simulate", "simulate_batch"]

LANE_MIN_CASES = 4  # per thread: below this many cases, the one-lane path is faster [cases]
EXTRAS_LANES = 1
"""The lane width of the rows whose variant runs one lane at a time whatever width the batch
asked (``kernel.one_lane_only``: a sampled controller, quantisers, compensators, static
friction, another controller): their branches keep the compiler from vectorising, and the
extras variant ran at 5.3 M lane-steps/s per core in 16 lanes against 7.6 M one lane at a time
(``Ts > 0``, 2026-11-26). The results are the same bit for bit."""
TIME_CHUNK = 2**14  # steps per kernel call; the references are sampled per call [steps]
"""Measured on 2 cores: sampling a reference costs the least per step at 2**14-2**15 steps (its
arrays stay in cache): a step input 5-8 ns/step, 4-6x less than at 2**16 or in one piece, a sine
35-45 ns/step. A kernel call's fixed cost (~11 us) is then < 1.5 % of a one-configuration call
(~1 ms). ``experiments/bench.py`` ("time chunks") prints both for 2**12, 2**14 and 2**16."""
BUDGET_ENV = "EMA_MAX_RECORD_BYTES"  # overrides the memory budget of one batch's results
TALLY = {"lane_steps": 0, "kernel_s": 0.0, "calls": 0}
"""Every :func:`simulate_batch` of this process adds its cases x steps, its time inside the
compiled kernel [s] and 1 call: benchmarks read it (reset it to zero first) for the kernel's
throughput inside a command. Counting only, never read by a computation."""
_THREAD = threading.local()  # per thread: ``serial`` (see serial_kernels)


@contextlib.contextmanager
def serial_kernels(on: bool = True) -> Iterator[None]:
    """While the block runs, every :func:`simulate_batch` of this thread uses the serial
    kernel entry points, whatever ``parallel`` its caller asks: no numba threading layer, safe
    in a thread among others (a Dask worker running several tasks at once; the workqueue layer
    aborts on concurrent launches). The results are the same bits."""
    previous = getattr(_THREAD, "serial", False)
    _THREAD.serial = previous or on
    try:
        yield
    finally:
        _THREAD.serial = previous


@dataclass
class BatchResult:
    """The output of one kernel call.

    P[n_cases, N_PARAMS]                 the SI parameter matrix that was run
    metrics[n_cases, N_METRICS]          SI metrics (columns: ``tables.METRICS``)
    signals[n_cases, n_out, n_sig]       SI signals every ``dec`` steps, or None: the first
                                         ``n_sig`` of ``sim.tables.SIGNALS`` (the paper's EMA's
                                         17, all of them for other descriptions:
                                         :func:`signal_count`)
    t_out[n_out]                         the recorded times [s]
    kernel_s                             wall time inside the compiled kernel calls [s]
    load_s                               time spent loading (or compiling) the kernel [s]: 0
                                         when this process had it loaded already
    """

    P: np.ndarray
    metrics: np.ndarray
    signals: np.ndarray | None
    t_out: np.ndarray
    dt: float
    n_steps: int
    dec: int
    kernel_s: float = 0.0
    load_s: float = 0.0

    @property
    def diverged(self) -> np.ndarray:
        """Boolean flag per case."""
        return self.metrics[:, [c.name for c in METRICS].index("diverged")] == 1.0

    def metrics_frame(self) -> pd.DataFrame:
        """Metrics in edge units, one row per case, units in the column names."""
        import pandas as pd

        data = {c.edge: self.metrics[:, j] * c.factor for j, c in enumerate(METRICS)}
        df = pd.DataFrame(data)
        df["diverged"] = df["diverged"].astype(bool)
        return df

    @property
    def signal_names(self) -> tuple[str, ...]:
        """The kernel names of the recorded signals, in the order of the last axis of
        ``signals`` (``theta_ref``, ``theta_load``, ...; ``sim.tables.SIGNALS``)."""
        return tuple(c.name for c in self.columns)

    @property
    def columns(self) -> tuple:
        """The :class:`sim.tables.Column` of each recorded signal (last axis of ``signals``)."""
        n = self.signals.shape[2] if self.signals is not None else PAPER_SIGNALS
        return SIGNALS[:n]

    def signal(self, name: str, case: int = 0, edge: bool = False) -> np.ndarray:
        """One recorded signal of one case by name (kernel name ``theta_load`` or edge column
        ``theta_load_deg``): SI, or in its edge unit with ``edge``."""
        if self.signals is None:
            raise EmaError("no signals were recorded (simulation.output_interval_s is null)")
        for j, c in enumerate(self.columns):
            if name in (c.name, c.edge):
                return self.signals[case, :, j] * (c.factor if edge else 1.0)
        raise EmaError(f"unknown signal {name!r}; expected one of "
                       f"{', '.join(c.name for c in self.columns)}")

    def signals_frame(self, case: int = 0) -> pd.DataFrame:
        """Recorded signals of one case in edge units, ``t_s`` first."""
        import pandas as pd

        if self.signals is None:
            raise ValueError("signals were not recorded (output interval None)")
        data = {"t_s": self.t_out}
        for j, c in enumerate(self.columns):
            data[c.edge] = self.signals[case, :, j] * c.factor
        return pd.DataFrame(data)


def lanes_for(n_cases: int, threads: int) -> int:
    """1 (every configuration alone, the fastest for a few) or :data:`kernel.LANES` (chunks
    advanced together in SIMD lanes), whichever is faster for ``n_cases`` on ``threads``."""
    return 1 if n_cases < LANE_MIN_CASES * max(threads, 1) else LANES


def check_sample_times(P: np.ndarray, dt: float) -> None:
    """Every controller sample time in ``P`` must be 0 (continuous) or a whole multiple of dt."""
    ts = P[:, INDEX["Ts"]]
    bad = off_grid(ts, dt)
    if np.any(bad):
        raise EmaError(f"controller sample time {float(ts[bad][0]):g} s must be a whole multiple "
                       f"of the integration step dt = {dt:g} s")


@functools.cache
def kernel_signature(variant: int = 0) -> tuple:
    """The numba argument types :func:`simulate_batch` calls a kernel entry point with for
    ``variant`` (a compile-time constant: a literal type)."""
    from numba import types

    f2 = types.Array(types.float64, 2, "C")
    f3 = types.Array(types.float64, 3, "C")
    i1 = types.Array(types.int64, 1, "C")
    i8, f8 = types.int64, types.float64
    # P, S, ref_pos, ref_vel, load_half, ext_half, step_info, ref_index, out_row, dt, n_steps,
    # k0, k1, dec, sig, met, variant
    return (f2, f3, f2, f2, f2, f2, f2, i1, i1, f8, i8, i8, i8, i8, f3, f2,
            types.literal(int(variant)))


def load_kernel(lanes: int, variant: int = 0) -> float:
    """Load the kernel entry point for ``lanes`` (1 or :data:`LANES`) in ``variant`` into this
    process -> the seconds it took (0 if it was loaded already).

    The dispatcher is asked to compile :func:`kernel_signature`, the exact argument types
    :func:`simulate_batch` passes: numba takes the machine code from its on-disk cache (or
    compiles and caches it the first time: announced on stderr, see ``sim.compiled``), without
    running anything, so later calls with those types do no more than run it.
    """
    from ema_cli.sim import compiled

    disp = KERNELS[lanes > 1]
    if not hasattr(disp, "compile"):  # NUMBA_DISABLE_JIT: plain Python
        return 0.0
    sig = kernel_signature(variant)
    if sig in disp.overloads:
        return 0.0
    t0 = time.perf_counter()
    with compiled.announce(compiled.entry_name(lanes, variant)):
        disp.compile(sig)
    return time.perf_counter() - t0


def entry_point(lanes: int, variant: int) -> Callable[..., None]:
    """The compiled entry point of ``variant`` as a plain function (the machine code's own
    wrapper: calling the dispatcher would retype the literal variant argument on every call,
    milliseconds each); loaded first (:func:`load_kernel`)."""
    disp = KERNELS[lanes > 1]
    if not hasattr(disp, "compile"):  # NUMBA_DISABLE_JIT: plain Python
        return disp
    load_kernel(lanes, variant)
    return disp.overloads[kernel_signature(variant)].entry_point


@functools.cache
def _pool(threads: int) -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="ema-kernel")


def blocks(n_units: int, threads: int) -> list[tuple[int, int]]:
    """``n_units`` (rows, or chunks of lanes) cut into at most ``threads`` contiguous blocks of
    near-equal size -> [(first, end)] (numba's static ``prange`` schedule)."""
    k = max(1, min(threads, n_units))
    edges = [n_units * i // k for i in range(k + 1)]
    return [(edges[i], edges[i + 1]) for i in range(k) if edges[i + 1] > edges[i]]


def _run_blocks(kernel: Callable[..., None], width: int, threads: int, Pv: np.ndarray,
                state: np.ndarray, qv: np.ndarray, ov: np.ndarray, args: tuple) -> None:
    """One call of an entry point over every row of ``Pv``, in blocks on ``threads`` threads
    (the entry points release the GIL; each block writes its own rows of the results and its
    own slice of ``state``, so the results are those of one serial call, bit for bit)."""
    n = Pv.shape[0]
    n_units = n if width == 1 else -(-n // LANES)
    parts = blocks(n_units, threads)
    if len(parts) == 1:
        kernel(Pv, state, *args[:5], qv, ov, *args[5:])
        return

    def one(part: tuple[int, int]) -> None:
        g0, g1 = part
        a, b = g0 * width, min(g1 * width, n)
        st = state[g0:g1] if state.shape[0] else state
        kernel(Pv[a:b], st, *args[:5], qv[a:b], ov[a:b], *args[5:])

    for f in [_pool(threads).submit(one, p) for p in parts]:
        f.result()


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**28 else f"{n / 2**20:.3g} MiB"


def record_budget() -> tuple[int | None, str]:
    """The most bytes one batch's results may take -> (bytes or None for no limit, where the
    number comes from): ``$EMA_MAX_RECORD_BYTES``, else half the available physical memory."""
    env = os.environ.get(BUDGET_ENV, "").strip()
    if env:
        try:
            value = float(env)
        except ValueError:
            value = -1.0
        if not (math.isfinite(value) and value > 0):
            raise EmaError(f"{BUDGET_ENV} must be a positive number of bytes, got {env!r}")
        return int(value), BUDGET_ENV
    try:
        avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):  # not available on this platform
        return None, "no limit"
    return avail // 2, f"half the available memory; {BUDGET_ENV} sets another limit"


def signal_count(P: np.ndarray) -> int:
    """How many signals a batch records (the first of ``sim.tables.SIGNALS``): the paper's
    EMA's :data:`sim.tables.PAPER_SIGNALS` unless a row is another actuator (a rigid axis, an
    amplifier, a load friction, another controller), which records them all (the drive's force
    and the load's friction too)."""
    from ema_cli.model.actuator import PAPER_MASK

    P = np.asarray(P)
    if P.shape[0] == 0:
        return PAPER_SIGNALS
    return N_SIGNALS if bool(np.any(variant_codes(P) > PAPER_MASK)) else PAPER_SIGNALS


def check_memory(n_cases: int, n_out: int, n_state: int, n_sig: int = N_SIGNALS) -> int:
    """Refuse a batch whose results (and carried state) would not fit the :func:`record_budget`
    -> the bytes needed."""
    record = n_cases * n_out * n_sig * 8
    need = record + n_cases * (N_METRICS + N_PARAMS) * 8 + n_state * 8
    budget, source = record_budget()
    if budget is not None and need > budget:
        raise EmaError(
            f"recording the signals needs {_gib(need)} ({n_cases} run(s) x {n_out} samples x "
            f"{n_sig} signals x 8 bytes, with the metrics), more than the {_gib(budget)} "
            f"allowed ({source}); use a larger simulation.output_interval_s or a shorter "
            "simulation.duration_s")
    return need


def simulate_batch(
    P: np.ndarray,
    refs: Sequence[InputSignal | Sampler | Reference],
    ref_index: np.ndarray | None,
    dt: float,
    n_steps: int,
    dec: int = 0,
    parallel: bool = False,
    lanes: int | None = None,
    progress: Callable[[float], None] | None = None,
    n_signals: int | None = None,
) -> BatchResult:
    """Run every row of ``P`` (SI parameter matrix) for ``n_steps`` steps of ``dt`` seconds.

    Row c follows ``refs[ref_index[c]]`` (``ref_index`` None: all follow ``refs[0]``): an
    :class:`InputSignal` (sampled per time chunk), a :class:`Sampler` from ``signals.sampler``
    for this grid, or a :class:`Reference` sampled for the whole grid. ``dec`` > 0 records
    signals every ``dec`` steps. ``parallel`` spreads blocks of rows over
    ``numba.get_num_threads()`` threads; ``lanes`` is 1 (each configuration alone) or
    :data:`kernel.LANES` (chunks in SIMD lanes), default :func:`lanes_for`; rows that need the
    extras variant run one lane at a time either way (:data:`EXTRAS_LANES`).
    ``progress(fraction)`` is called after each time chunk with the fraction of the steps done.
    Results are bit-identical whatever ``parallel``, ``lanes`` and
    :data:`TIME_CHUNK` are. ``n_signals`` how many signals to record (default
    :func:`signal_count`; a sweep passes its own for every batch). Raises EmaError when the
    recorded signals would not fit in memory (:func:`check_memory`).
    """
    import numba

    P = np.require(P, dtype=np.float64, requirements=["C", "A", "W"])
    if P.ndim != 2 or P.shape[1] != N_PARAMS:
        raise ValueError(f"P must have shape (n_cases, {N_PARAMS}), got {P.shape}")
    check_sample_times(P, dt)
    dt, n_steps, dec = float(dt), int(n_steps), int(dec)
    parallel = parallel and not getattr(_THREAD, "serial", False)
    n_cases = P.shape[0]
    if ref_index is None:
        ref_index = np.zeros(n_cases, dtype=np.int64)
    ref_index = np.require(ref_index, dtype=np.int64, requirements=["C", "A", "W"])
    sources = [sampler(r, dt, n_steps) for r in refs]
    info = np.ascontiguousarray(np.stack([s.step_info for s in sources]), dtype=np.float64)
    with_load = any(s.has_load for s in sources)
    with_ext = any(s.has_ext for s in sources)
    threads = numba.get_num_threads() if parallel else 1
    if lanes is None:
        lanes = lanes_for(n_cases, threads)
    if lanes not in (1, LANES):
        raise ValueError(f"lanes must be 1 or {LANES}, got {lanes}")
    chunk = max(int(TIME_CHUNK), 1)
    n_calls = -(-(n_steps + 1) // chunk)
    n_out = n_steps // dec + 1 if dec > 0 else 0
    # the rows sorted by the kernel variant they need (model.actuator: friction and its
    # exponent, the paper cascade's extras, the actuator's structure): each variant's rows are
    # run by that variant's entry point (compiled the first time it is needed), in chunks of
    # their own; each row writes its results straight into its own row of sig and met
    if with_ext:  # each row's input signal held or interpolated (the kernel's ext_hold)
        hold = np.array([bool(s.ext_hold) for s in sources])
        P = P.copy()
        P[:, INDEX["ext_hold"]] = hold[ref_index].astype(np.float64)
    order = variant_order(P)
    codes = variant_codes(P[order])  # sorted: each variant's rows contiguous
    check_inputs(codes, with_ext)
    parts = []  # (variant, lane width, first row, end row, state shape) in sorted order
    for code in np.unique(codes):
        rows_v = np.flatnonzero(codes == code)
        a, b = int(rows_v[0]), int(rows_v[-1]) + 1
        width = EXTRAS_LANES if one_lane_only(code) else lanes
        variant = int(variant_keys(np.array([code]), width)[0])
        groups = (b - a) if width == 1 else -(-(b - a) // LANES)
        shape = (groups if n_calls > 1 else 0, N_ROWS, width)
        parts.append((variant, width, a, b, shape))
    n_sig = signal_count(P) if n_signals is None else int(n_signals)
    check_memory(n_cases, n_out, sum(math.prod(p[4]) for p in parts), n_sig)
    sig = np.full((n_cases, n_out, n_sig), np.nan)
    met = np.empty((n_cases, N_METRICS))
    identity = bool(np.all(order == np.arange(n_cases)))
    Pk = P if identity else np.ascontiguousarray(P[order])
    qk = ref_index if identity else np.ascontiguousarray(ref_index[order])
    out_row = np.ascontiguousarray(order, dtype=np.int64)
    calls = []
    load_s = 0.0
    for variant, width, a, b, shape in parts:
        load_s += load_kernel(width, variant)  # 0 when loaded already
        kernel = entry_point(width, variant)
        state = np.empty(shape)
        # lanes of the state that hold a real row (the rest repeat the first row of a chunk)
        real = (np.arange(shape[0])[:, None] * width + np.arange(width)[None, :]) < (b - a)
        calls.append((kernel, variant, np.ascontiguousarray(Pk[a:b]), state,
                      np.ascontiguousarray(qk[a:b]), np.ascontiguousarray(out_row[a:b]), real))
    kernel_s = 0.0
    k0 = 0
    while k0 <= n_steps:
        k1 = min(k0 + chunk, n_steps + 1)
        if n_calls > 1 and k0 > 0 and not any(np.any(c[3][:, ALIVE_ROW, :][c[6]] != 0.0)
                                              for c in calls):
            k0 = n_steps + 1  # every row has diverged: only the metrics are left to finish
            k1 = k0
        pos, vel, load, ext = _inputs(sources, k0, k1, with_load, with_ext)
        t0 = time.perf_counter()
        for kernel, variant, Pv, state, qv, ov, _ in calls:
            width = state.shape[2]
            _run_blocks(kernel, width, threads, Pv, state, qv, ov,
                        (pos, vel, load, ext, info, dt, n_steps, k0, k1, dec, sig, met, variant))
        kernel_s += time.perf_counter() - t0
        if progress is not None:
            progress(min(k1, n_steps + 1) / (n_steps + 1))
        k0 = k1
    t_out = np.arange(n_out) * (dec * dt)
    TALLY["lane_steps"] += n_cases * n_steps
    TALLY["kernel_s"] += kernel_s
    TALLY["calls"] += 1
    return BatchResult(P, met, sig if dec > 0 else None, t_out, dt, n_steps, dec, kernel_s,
                       load_s)


def _rows(arrays: Sequence[np.ndarray]) -> np.ndarray:
    """The 1-D ``arrays`` (equal lengths) as the rows of one C-contiguous, writable float64
    array (a view when there is only one and it qualifies)."""
    a = arrays[0][None] if len(arrays) == 1 else np.stack(arrays)
    return np.require(a, dtype=np.float64, requirements=["C", "A", "W"])


def _inputs(sources: Sequence, k0: int, k1: int, with_load: bool,
            with_ext: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's input arrays for steps k0..k1-1: (ref_pos, ref_vel, load_half, ext_half),
    one row per reference (load_half and ext_half have no columns when no reference has one)."""
    no_columns = np.zeros((len(sources), 0))
    if k1 <= k0:  # nothing to sample
        return no_columns, no_columns, no_columns, no_columns
    parts = [s.chunk(k0, k1) for s in sources]
    pos = _rows([p[0] for p in parts])
    vel = _rows([p[1] for p in parts])
    load = no_columns
    if with_load:
        load = _rows([p[2] if p[2] is not None else np.zeros(pos.shape[1]) for p in parts])
    ext = no_columns
    if with_ext:
        exts = [s.ext_chunk(k0, k1) for s in sources]
        ext = _rows([e if e is not None else np.zeros(pos.shape[1]) for e in exts])
    return pos, vel, load, ext


def check_inputs(codes: np.ndarray, with_ext: bool) -> None:
    """A variant that reads the input signal (a disturbance added to the controller's output,
    or the actuation of a plant without controller) needs one."""
    from ema_cli.model.actuator import B_EXT

    if not with_ext and np.any((np.asarray(codes) >> B_EXT) & 1):
        raise EmaError("this actuator reads an input signal (controller none: the actuation; "
                       "dist_out: a disturbance on the controller's output) and the run gives "
                       "none (input.signal: a log channel or a CSV profile)")


def simulate(
    params: Mapping[str, float],
    signal: InputSignal,
    duration: float,
    dt: float = DEFAULT_DT,
    output_interval: float | None = DEFAULT_OUTPUT_INTERVAL,
    progress: Callable[[float], None] | None = None,
) -> BatchResult:
    """Simulate one resolved SI configuration (see ``model.params.resolve``)."""
    n_steps, dec = plan_steps(duration, dt, output_interval)
    P = np.array([to_row(params)])
    return simulate_batch(P, [signal], None, dt, n_steps, dec, progress=progress)

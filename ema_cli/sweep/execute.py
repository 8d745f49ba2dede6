"""Sweep chunks on the executor (``sweep.executor``): in-process (serial or numba threads),
loky or dask.

One level of parallelism at a time: either threads over blocks of one chunk in this
process (backend ``threads``), or worker processes (``loky``) / a Dask cluster (``dask``) each
running whole chunks with numba pinned to one thread. The kernel is warmed in the parent before
any worker starts, so workers only load it from numba's on-disk cache. Each chunk is one kernel
call; its results come back to the parent, which alone writes files. A chunk whose worker was
lost is run again; one lost twice is reported as its jobs' error.
"""

from __future__ import annotations

import functools
import math
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ema_cli.sim.runner import simulate_batch
from ema_cli.sim.signals import InputSignal, Sampler, sampler
from ema_cli.sim.tables import N_SIGNALS
from ema_cli.sweep.executor import (  # noqa: F401 (re-exported: the sweep's names for them)
    BACKENDS,
    DASK_HINT,
    LOCAL_DEFAULT,
    SCHEDULER_ADDRESS,
    Executor,
    Failure,
    Task,
    check_dask,
    cpu_count,
    resolve_backend,
    resolve_workers,
)

CHUNKS_PER_WORKER = 4  # chunks per worker: progress granularity and load balance [-]
MAX_CHUNK_CASE_STEPS = 30_000_000  # cap on jobs*steps per worker per chunk (~1 s of kernel) [-]
MAX_CHUNK_SIGNAL_BYTES = 256 * 2**20  # cap on the recorded signals one chunk returns [bytes]
WARM_STEPS = 4  # steps of the tiny run that loads the compiled kernel before workers start [-]


@dataclass
class ChunkOutput:
    """What a worker returns for one chunk.

    metrics[n, N_METRICS] SI; signals[n, n_out, N_SIGNALS] SI or None; ``kernel_s`` the wall
    time of the kernel call [s]; ``error`` the text of an exception (then the arrays are None).
    """

    metrics: np.ndarray | None
    signals: np.ndarray | None
    kernel_s: float
    error: str | None = None


def chunk_sizes(n: int, n_steps: int, workers: int, backend: str, n_out: int,
                chunk_size: int | None = None, n_signals: int = N_SIGNALS) -> list[int]:
    """Split ``n`` pending jobs into chunks (each one kernel call) -> list of chunk lengths.

    About ``CHUNKS_PER_WORKER`` chunks per worker, each holding at most
    ``MAX_CHUNK_CASE_STEPS`` job-steps per thread and ``MAX_CHUNK_SIGNAL_BYTES`` of signals.
    """
    if n == 0:
        return []
    if chunk_size is None:
        threads = workers if backend == "threads" else 1
        size = math.ceil(n / (CHUNKS_PER_WORKER * workers))
        size = min(size, max(1, MAX_CHUNK_CASE_STEPS * threads // max(n_steps, 1)))
        if n_out > 0:
            size = min(size, max(1, MAX_CHUNK_SIGNAL_BYTES // (n_out * n_signals * 8)))
        size = max(size, min(threads, n))
    else:
        size = chunk_size
    full, rest = divmod(n, size)
    return [size] * full + ([rest] if rest else [])


Source = InputSignal | Sampler
"""A chunk's reference: the plan's :class:`Sampler` (prepared once per run, sent to workers
with each chunk) or an :class:`InputSignal` (prepared once per process)."""


@functools.lru_cache(maxsize=4)
def _prepared(signal: Source, dt: float, n_steps: int) -> Sampler:
    """An InputSignal prepared for the grid once per process (a CSV profile read once)."""
    return sampler(signal, dt, n_steps)


def _reference(source: Source, dt: float, n_steps: int) -> Sampler:
    """``source`` ready for the grid: a Sampler as it is, an InputSignal prepared once."""
    if isinstance(source, Sampler):
        return source
    return _prepared(source, dt, n_steps)


def run_chunk(P: np.ndarray, signal: Source, dt: float, n_steps: int, dec: int,
              threads: int, n_signals: int | None = None) -> ChunkOutput:
    """Worker side: one kernel call on the parameter matrix ``P`` (SI) with ``threads`` threads.

    ``threads`` = 0 runs the kernel in this thread; ``threads`` >= 1 spreads blocks of the
    chunk over that many threads (``sim.runner.simulate_batch``; on a Dask worker running
    several task threads, the executor makes it one thread). Both run the same compiled entry
    point and give bit-identical results. Exceptions are
    returned as text so one bad chunk does not stop the sweep. ``n_signals``: the signals
    every chunk of the sweep records (``sim.runner.signal_count`` of all its jobs).
    """
    import numba

    previous = numba.get_num_threads()
    try:
        if threads > 0:
            numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        ref = _reference(signal, dt, n_steps)
        res = simulate_batch(P, [ref], None, dt, n_steps, dec, parallel=threads > 0,
                             n_signals=n_signals)
        return ChunkOutput(res.metrics, res.signals, res.kernel_s)
    except Exception as exc:  # reported per job in the manifest; the sweep goes on
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" ({last[0].filename}:{last[0].lineno})" if last else ""
        return ChunkOutput(None, None, 0.0, f"{type(exc).__name__}: {exc}{where}")
    finally:
        numba.set_num_threads(previous)


def warm_kernel(signal: Source, dt: float, threads: int) -> float:
    """Compile or load the kernel entry points (one lane and SIMD lanes), here, before workers
    start, with a tiny run of each [s]. A Sampler's first steps are taken as they are (not sampled
    again)."""
    from ema_cli.model.params import resolve, to_row
    from ema_cli.sim.kernel import LANES
    from ema_cli.sim.signals import Reference

    t0 = time.perf_counter()
    P = np.array([to_row(resolve())])
    ref: Source | Reference = signal
    if isinstance(signal, Sampler):
        pos, vel, load = signal.chunk(0, min(WARM_STEPS + 1, signal.n_steps + 1))
        n = len(vel) - 1
        ref = Reference(pos[:2 * n + 1], vel, signal.step_info,
                        None if load is None else load[:2 * n + 1])
        steps = n
    else:
        steps = WARM_STEPS
    for lanes in (1, LANES):
        simulate_batch(P, [ref], None, dt, steps, 1, parallel=threads > 0, lanes=lanes)
    return time.perf_counter() - t0


OnChunk = Callable[[int, ChunkOutput], None]


def execute(chunks: Sequence[np.ndarray], signal: Source, dt: float, n_steps: int, dec: int,
            backend: str, workers: int, on_chunk: OnChunk, scheduler: str | None = None,
            n_signals: int | None = None, labels: Sequence[str] | None = None
            ) -> list[tuple[str, str]]:
    """Run every chunk (a parameter matrix) on the backend (``sweep.executor``) and call
    ``on_chunk(i, output)`` in the parent as each finishes (in completion order). A chunk
    whose worker was lost is run again; one lost twice comes back as an error naming its
    ``labels[i]`` (its jobs are marked failed). KeyboardInterrupt stops the workers and
    propagates. Returns the chunks run again: (label, why) each."""
    if not chunks:
        return []
    with Executor(backend, workers, scheduler) as ex:
        threads = workers if ex.backend == "threads" else 1
        if ex.backend == "dask":  # warm the kernel on every worker once: no race to compile
            ex.run_on_workers(warm_kernel, signal, dt, 0)
        tasks = (Task(run_chunk, (P, signal, dt, n_steps, dec, threads, n_signals),
                      labels[i] if labels else f"chunk {i + 1}") for i, P in enumerate(chunks))
        for i, out in ex.map(tasks, ordered=False, failures="return"):
            if isinstance(out, Failure):
                out = ChunkOutput(None, None, 0.0, out.message)
            on_chunk(i, out)
        return ex.retries


MIN_BLOCK_CASE_STEPS = 10_000_000
"""Fewest cases x steps in one block of a batch cut over remote workers (:func:`spread_batch`):
about 0.2 s of kernel on one core at ``progress.CPU_S_PER_STEP``, against the Dask round trip
of a block (``make bench``: experiments/bench_scale.py measures it)."""


def batch_task(P: np.ndarray, refs: Sequence[Any], ref_index: np.ndarray, dt: float,
               n_steps: int, dec: int) -> Any:
    """Worker side of :func:`spread_batch`: one kernel call (numba's threads as the executor
    set them)."""
    return simulate_batch(P, refs, ref_index, dt, n_steps, dec, parallel=True)


def spread_batch(P: np.ndarray, refs: Sequence[Any], ref_index: np.ndarray, dt: float,
                 n_steps: int, what: str = "rows") -> Any:
    """``simulate_batch(P, refs, ref_index, dt, n_steps)`` (metrics only) on the current
    executor (``sweep.executor.current``): in this process one batched call; on remote workers
    the rows cut into one block per worker (each at least :data:`MIN_BLOCK_CASE_STEPS`),
    merged back in row order -> a ``BatchResult`` with the same bits (``kernel_s`` summed
    over the blocks). ``what`` names the rows in a block's label."""
    from ema_cli.sim.runner import BatchResult
    from ema_cli.sweep.executor import current, split

    ex = current()
    bounds = split(P.shape[0], math.ceil(MIN_BLOCK_CASE_STEPS / max(n_steps, 1)))
    if not ex.remote or len(bounds) < 2:
        return simulate_batch(P, refs, ref_index, dt, n_steps, 0, parallel=True)
    parts = ex.run(Task(batch_task, (P[a:b], refs, ref_index[a:b], dt, n_steps, 0),
                        f"{what} {a}-{b - 1}") for a, b in bounds)
    first = parts[0]
    return BatchResult(P, np.concatenate([p.metrics for p in parts]), None, first.t_out,
                       first.dt, first.n_steps, 0, sum(p.kernel_s for p in parts),
                       sum(p.load_s for p in parts))

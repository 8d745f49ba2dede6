"""Parallel execution of sweep chunks: in-process (serial or numba threads), loky or dask.

One level of parallelism at a time: either threads over blocks of one chunk in this
process (backend ``threads``), or worker processes (``loky``) / a Dask cluster (``dask``) each
running whole chunks with numba pinned to one thread. The kernel is warmed in the parent before
any worker starts, so workers only load it from numba's on-disk cache. Each chunk is one kernel
call; its results come back to the parent, which alone writes files.
"""

from __future__ import annotations

import functools
import math
import os
import re
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ema_cli.errors import EmaError
from ema_cli.sim.runner import simulate_batch
from ema_cli.sim.signals import InputSignal, Sampler, sampler
from ema_cli.sim.tables import N_SIGNALS

BACKENDS = ("auto", "loky", "threads", "dask")
LOCAL_DEFAULT = "threads"
"""What ``auto`` means on one machine: threads in this process (numba's thread count). Measured with
experiments/bench_sweep.py (1,000 jobs of 1 s, 2 cores, fresh processes, medians of 5): threads
3.85 s end to end, loky 4.73 s; the kernel time is the same (3.43 s vs 3.46 s), loky's extra
~1 s is starting the workers and loading the kernel in each."""
CHUNKS_PER_WORKER = 4  # chunks per worker: progress granularity and load balance [-]
MAX_CHUNK_CASE_STEPS = 30_000_000  # cap on jobs*steps per worker per chunk (~1 s of kernel) [-]
MAX_CHUNK_SIGNAL_BYTES = 256 * 2**20  # cap on the recorded signals one chunk returns [bytes]
WARM_STEPS = 4  # steps of the tiny run that loads the compiled kernel before workers start [-]
DASK_HINT = "the dask backend needs dask.distributed: pip install 'ema-cli[dask]'"


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


def cpu_count() -> int:
    """Cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def resolve_workers(n_jobs: int | None) -> int:
    """``n_jobs`` (None or -1: all cores) -> a worker count >= 1."""
    if n_jobs is None or n_jobs == -1:
        return cpu_count()
    if n_jobs < 1:
        raise EmaError(f"n_jobs must be >= 1, or -1 for all cores, got {n_jobs}")
    return n_jobs


def resolve_backend(backend: str | None, workers: int) -> str:
    """The backend to run: ``auto`` picks the local default; one worker runs serially."""
    backend = backend or "auto"
    if backend not in BACKENDS:
        raise EmaError(f"unknown backend '{backend}'; expected one of {', '.join(BACKENDS)}")
    if backend == "auto":
        backend = LOCAL_DEFAULT
    if backend in ("loky", "threads") and workers == 1:
        return "serial"
    return backend


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

    ``threads`` = 0 runs the kernel in this thread (used on Dask workers); ``threads`` >= 1
    spreads blocks of the chunk over that many threads (``sim.runner.simulate_batch``). Both
    run the same compiled entry point and give bit-identical results. Exceptions are
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
            n_signals: int | None = None) -> None:
    """Run every chunk (a parameter matrix) and call ``on_chunk(i, output)`` in the parent as
    each finishes (in completion order). KeyboardInterrupt stops the workers and propagates.
    """
    if not chunks:
        return
    if backend in ("serial", "threads"):
        threads = 1 if backend == "serial" else workers
        for i, P in enumerate(chunks):
            on_chunk(i, run_chunk(P, signal, dt, n_steps, dec, threads, n_signals))
        return
    if backend == "loky":
        _execute_joblib(chunks, signal, dt, n_steps, dec, workers, on_chunk, "loky", threads=1,
                        n_signals=n_signals)
        return
    if backend == "dask":
        _execute_dask(chunks, signal, dt, n_steps, dec, on_chunk, scheduler, n_signals)
        return
    raise EmaError(f"unknown backend '{backend}'; expected one of {', '.join(BACKENDS)}")


def _indexed(i: int, P: np.ndarray, signal: Source, dt: float, n_steps: int, dec: int,
             threads: int, n_signals: int | None = None) -> tuple[int, ChunkOutput]:
    return i, run_chunk(P, signal, dt, n_steps, dec, threads, n_signals)


def _execute_joblib(chunks: Sequence[np.ndarray], signal: Source, dt: float, n_steps: int,
                    dec: int, workers: int, on_chunk: OnChunk, backend: str | None,
                    threads: int, n_signals: int | None = None) -> None:
    """joblib over the chunks; ``backend`` None: the one set by ``joblib.parallel_config``."""
    from joblib import Parallel, delayed

    tasks = (delayed(_indexed)(i, P, signal, dt, n_steps, dec, threads, n_signals)
             for i, P in enumerate(chunks))
    kwargs = {} if backend is None else {"backend": backend}
    par = Parallel(n_jobs=workers, return_as="generator_unordered", **kwargs)
    for i, out in par(tasks):
        on_chunk(i, out)


SCHEDULER_ADDRESS = re.compile(
    r"(?:(?:tcp|tls|ucx|ws|wss)://)?(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):[0-9]{1,5}")
"""What a dask scheduler address looks like: [tcp://]host:port (tls, ucx, ws(s) too)."""


def check_dask(scheduler: str | None) -> None:
    """Refuse the dask backend early: no scheduler address, or dask.distributed missing."""
    if not scheduler:
        raise EmaError("the dask backend needs a scheduler address: --scheduler ADDRESS "
                       "(or parallel.scheduler in the config)")
    if not SCHEDULER_ADDRESS.fullmatch(scheduler.strip()):
        raise EmaError(f"--scheduler {scheduler!r} is not a dask scheduler address; expected "
                       "tcp://HOST:PORT or HOST:PORT (or parallel.scheduler in the config)")
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise EmaError(DASK_HINT) from None


def _execute_dask(chunks: Sequence[np.ndarray], signal: Source, dt: float, n_steps: int,
                  dec: int, on_chunk: OnChunk, scheduler: str | None,
                  n_signals: int | None = None) -> None:
    check_dask(scheduler)
    from dask.distributed import Client
    from joblib import parallel_config

    try:
        client = Client(scheduler, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise EmaError(f"cannot reach the dask scheduler at {scheduler!r}: {exc}", 1) from None
    try:
        n_workers = max(1, sum(client.nthreads().values()))
        # warm the kernel on every worker once, so chunks do not race to compile it
        client.run(warm_kernel, signal, dt, 0)
        with client.as_current(), parallel_config(backend="dask"):
            _execute_joblib(chunks, signal, dt, n_steps, dec, n_workers, on_chunk, None,
                            threads=0, n_signals=n_signals)
    finally:
        client.close()

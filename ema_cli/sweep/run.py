"""The sweep runner: plan, look up the cache, execute what is missing (``compute_sweep``).

``compute_sweep`` returns a :class:`SweepResult`: the metrics table (one row per job) and
access to each job's decimated time series. It writes nothing but the job cache (and only when
given one); ``api.study.run_sweep`` (the one route of ``ema sweep`` and of the paper
reproduction) plans the config once and hands this the plan and the output folder's sink
(``report.sweep_report.SweepFolder``) as the ``on_start`` / ``on_signals`` / ``on_finish``
hooks.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.progress import announce_size
from ema_cli.sim.runner import check_memory
from ema_cli.sim.tables import MET, N_METRICS, N_SIGNALS
from ema_cli.sweep.cache import JobCache, SignalsRule, signals_rule
from ema_cli.sweep.execute import (
    ChunkOutput,
    check_dask,
    chunk_sizes,
    execute,
    resolve_backend,
    resolve_workers,
    warm_kernel,
)
from ema_cli.sweep.plan import Plan, plan_sweep
from ema_cli.sweep.result import (
    DIVERGED,
    FAILED,
    JOB_COLUMN,
    OK,
    PENDING,
    TIME_COLUMN,
    SweepResult,
    metrics_frame,
    read_timeseries,
)

__all__ = ["DIVERGED", "FAILED", "JOB_COLUMN", "OK", "PENDING", "TIME_COLUMN", "OnSignals",
           "SweepResult", "compute_sweep", "metrics_frame", "read_timeseries"]

PROGRESS_REFRESH_PER_S = 4  # progress bar refresh rate [1/s]
CACHED_SIGNAL_BATCH_BYTES = 64 * 2**20  # cached signals read (and handed on) at a time [bytes]
TIMINGS = ("lookup", "warm", "execute", "kernel", "store", "signals", "writes")
"""The timings every sweep reports (wall seconds; see ``SweepResult``)."""

OnSignals = Callable[[Sequence[int], Sequence[int], np.ndarray], None]
"""``on_signals(jobs, rows, signals)``: job ``jobs[i]`` (index) recorded ``signals[rows[i]]``
(SI, [n_out, N_SIGNALS])."""

class _Progress:
    """A rich progress bar with ETA (or nothing when ``enabled`` is False)."""

    def __init__(self, total: int, enabled: bool, label: str) -> None:
        from ema_cli.progress import report

        self.bar = None
        self.total, self.done, self.enabled = total, 0, enabled
        if total > 0:
            report("simulations", 0, total, bar=enabled)
        if enabled and total > 0:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self.bar = Progress(TextColumn("{task.description}"), BarColumn(),
                                MofNCompleteColumn(), TextColumn("jobs"), TimeElapsedColumn(),
                                TextColumn("ETA"), TimeRemainingColumn(),
                                console=Console(stderr=True),
                                refresh_per_second=PROGRESS_REFRESH_PER_S)
            self.task = self.bar.add_task(label, total=total)

    def __enter__(self) -> _Progress:
        if self.bar is not None:
            self.bar.start()
        return self

    def advance(self, n: int) -> None:
        from ema_cli.progress import report

        self.done += n
        report("simulations", self.done, self.total, bar=self.enabled)  # the API's hook too
        if self.bar is not None:
            self.bar.advance(self.task, n)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()


def compute_sweep(
    plan: Plan | StudyConfig,
    n_jobs: int | None = None,
    backend: str | None = None,
    force: bool = False,
    progress: bool = True,
    *,
    scheduler: str | None = None,
    chunk_size: int | None = None,
    cache_dir: Path | None = None,
    base_dir: Path | None = None,
    source: str = "config",
    on_start: Callable[[Plan], None] | None = None,
    on_signals: OnSignals | None = None,
    on_finish: Callable[[SweepResult, bool], None] | None = None,
    keep_signals: bool = True,
) -> SweepResult:
    """Run every job of a sweep (finished ones from the cache) and return the result.

    plan       the resolved sweep (``sweep.plan.plan_sweep``: jobs, parameter rows, the sampled
               reference), or a validated StudyConfig, planned here with ``base_dir``/``source``
    n_jobs     workers; None: ``cfg.parallel.n_jobs`` (None there: all cores); the dask
               backend uses every thread of the cluster instead
    backend    auto | loky | threads | dask; None: ``cfg.parallel.backend``
    force      recompute every job even if it is cached
    progress   show a progress bar with ETA on stderr
    scheduler  dask scheduler address (default ``cfg.parallel.scheduler``)
    chunk_size jobs per kernel call (default ``cfg.parallel.chunk_size``, else automatic)
    cache_dir  job cache folder; None: no cache (nothing is created on disk, every job is
               computed and the recorded signals are kept in memory)
    base_dir   folder relative CSV input profiles are looked up in (the config's folder)
    source     name of the config in error messages
    on_start   ``on_start(plan)``: called once the plan and backend are ready, before the
               cache is opened and any job runs (the report layer creates the output folder)
    on_signals ``on_signals(jobs, rows, signals)`` (see :data:`OnSignals`): called with the
               recorded signals of every finished job once, cached ones first, then each
               chunk's as it completes (the report layer streams signals.parquet here)
    on_finish  ``on_finish(result, aborted)``: called when execution ends, also on Ctrl-C or
               an error (``aborted`` True, the result holds the finished jobs) before the
               exception propagates (the report layer writes the outputs here)
    keep_signals  keep the recorded signals that do not go into the cache in memory, for the
               result's ``signals`` / ``timeseries``; False: ``on_signals`` stores them where
               the result reads them back (the report layer's signals.parquet)

    Finished jobs are stored in the cache as each chunk completes: always their metrics, their
    recorded signals only when ``sweep.cache.signals_rule`` says storing them costs little next
    to computing them (a later sweep that needs the signals of a job whose signals are not
    cached recomputes that job, bit-identical); on Ctrl-C ``on_finish``
    runs and KeyboardInterrupt is re-raised. A job whose chunk raised is marked failed (error
    text in the result) and the sweep goes on; an exception in ``on_signals`` stops it. Cache
    entries that fail their checksum are recomputed and reported (``cache_corrupt``, a
    warning). Writes nothing but the job cache.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = dict.fromkeys(TIMINGS, 0.0)
    if not isinstance(plan, Plan):
        plan = plan_sweep(plan, base_dir, source)
    timings["plan"] = time.perf_counter() - t_start
    setup = _setup(plan, n_jobs, backend, scheduler, chunk_size, cache_dir)
    if on_start is not None:  # first: a bad output folder is reported before anything is made
        on_start(plan)
    run = _Run(plan, setup, on_signals, keep_signals, timings)
    aborted = True
    try:
        run.open_cache(cache_dir)
        pending = run.look_up(force)
        run.execute(pending, progress)
        aborted = False
    except KeyboardInterrupt:
        run.interrupted = True
        raise
    finally:
        run.close()
        result = run.result()
        if on_finish is not None:
            on_finish(result, aborted)
        timings["total"] = time.perf_counter() - t_start
    return result


@dataclass(frozen=True)
class _Setup:
    """How a sweep executes: workers, backend, dask scheduler, jobs per chunk (None: auto)."""

    workers: int
    backend: str
    scheduler: str | None
    chunk_size: int | None


def _setup(plan: Plan, n_jobs: int | None, backend: str | None, scheduler: str | None,
           chunk_size: int | None, cache_dir: Path | None) -> _Setup:
    """Resolve the execution options over ``plan.cfg.parallel`` and refuse, before anything is
    written, a dask backend without a scheduler, a chunk whose recording does not fit in
    memory and a cache folder that cannot be made."""
    par = plan.cfg.parallel
    workers = resolve_workers(n_jobs if n_jobs is not None else par.n_jobs)
    setup = _Setup(workers, resolve_backend(backend or par.backend, workers),
                   scheduler or par.scheduler, chunk_size or par.chunk_size)
    if setup.backend == "dask":
        check_dask(setup.scheduler)
    n_out = _n_out(plan)
    if n_out > 0 and plan.jobs:  # one chunk's recording must fit
        size = chunk_sizes(plan.n_unique, plan.n_steps, workers, setup.backend, n_out,
                           setup.chunk_size, plan.n_signals)[0]
        check_memory(size, n_out, 0, plan.n_signals)
    if cache_dir is not None:
        check_cache_dir(Path(cache_dir))
    return setup


def _n_out(plan: Plan) -> int:
    """Samples recorded per job (0: none)."""
    return plan.n_steps // plan.dec + 1 if plan.dec > 0 else 0


class _Run:
    """One sweep being executed: the job states, the job cache and the chunks in flight.

    Jobs with the same cache key are computed once (``by_key``: key -> job indices, ``first``:
    key -> the job that stands for it). Finished chunks are stored in the cache as they
    complete (in a thread of their own when their signals are cached: one in flight) and their
    signals handed to ``on_signals``.
    """

    def __init__(self, plan: Plan, setup: _Setup, on_signals: OnSignals | None,
                 keep_signals: bool, timings: dict[str, float]) -> None:
        self.plan, self.setup, self.timings = plan, setup, timings
        self.on_signals, self.keep_signals = on_signals, keep_signals
        n = len(plan.jobs)
        self.n_out = _n_out(plan)
        self.metrics = np.full((n, N_METRICS), np.nan)
        self.status, self.errors = [PENDING] * n, [""] * n
        self.memory: dict[str, np.ndarray] = {}
        self.by_key: dict[str, list[int]] = {}
        for j in plan.jobs:
            self.by_key.setdefault(j.key, []).append(j.index)
        self.first = {key: idxs[0] for key, idxs in self.by_key.items()}
        self.computed = self.cached = 0
        self.sink_failed = self.interrupted = False
        self.warnings: list[str] = []
        self.rule: SignalsRule | None = None
        self.cache: JobCache | None = None
        self.pool: ThreadPoolExecutor | None = None
        self.storing: list[Future[float]] = []  # the chunk being stored (one at most)
        self.chunk_keys: list[list[str]] = []
        self.done_chunks: set[int] = set()
        self.bar = _Progress(0, False, "")

    @property
    def cache_signals(self) -> bool:
        return self.rule is not None and self.rule.cache

    # ------------------------------------------------------------------ steps
    def open_cache(self, cache_dir: Path | None) -> None:
        """Open the job cache (None: no cache) and decide whether it stores signals."""
        if cache_dir is None:
            return
        if self.n_out > 0:
            self.rule = signals_rule(self.plan.n_steps, self.n_out, self.setup.workers,
                                     self.plan.n_signals)
        self.cache = JobCache(cache_dir)
        if self.cache_signals:
            self.pool = ThreadPoolExecutor(1, thread_name_prefix="ema-cache-store")

    def look_up(self, force: bool) -> list[str]:
        """Finish the jobs the cache holds intact -> the keys still to compute, in job order."""
        t0 = time.perf_counter()
        pending = _lookup(self.cache, self.by_key, force, self.plan.dec, self.n_out,
                          self.finish, self.hand_on, self.plan.n_signals)
        pending.sort(key=self.first.__getitem__)
        announce_size(len(pending), self.plan.n_steps, self.setup.workers)
        self.cached = len(self.by_key) - len(pending)
        if self.cache is not None and self.cache.corrupt:
            self.warnings.append(_corrupt_warning(self.cache))
        self.timings["lookup"] = time.perf_counter() - t0 - self.timings["signals"]
        return pending

    def execute(self, pending: list[str], progress: bool) -> None:
        """Compute the ``pending`` keys in chunks (one kernel call each) on the backend."""
        plan, setup, timings = self.plan, self.setup, self.timings
        sizes = chunk_sizes(len(pending), plan.n_steps, setup.workers, setup.backend,
                            self.n_out, setup.chunk_size, plan.n_signals)
        bounds = np.cumsum([0, *sizes])
        self.chunk_keys = [pending[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        chunks = [plan.P([plan.jobs[self.first[k]] for k in keys]) for keys in self.chunk_keys]
        reference = plan.reference if plan.reference is not None else plan.signal
        label = f"{plan.cfg.name}: {len(pending)} to run, {self.cached} cached"
        self.bar = _Progress(sum(len(self.by_key[k]) for k in pending), progress, label)
        with self.bar:
            if chunks and setup.backend != "dask":
                timings["warm"] = warm_kernel(reference, plan.dt, 1)  # the threaded run
            t1 = time.perf_counter()
            try:
                retried = execute(chunks, reference, plan.dt, plan.n_steps, plan.dec,
                                  setup.backend, setup.workers, self.on_chunk,
                                  setup.scheduler, plan.n_signals,
                                  [self.chunk_label(keys) for keys in self.chunk_keys])
                self.warnings += [f"{label}: run again ({why})" for label, why in retried]
                tw = time.perf_counter()
                self.settle()
                timings["writes"] += time.perf_counter() - tw
            except (KeyboardInterrupt, EmaError):
                raise
            except Exception as exc:  # a worker died: unfinished chunks are marked failed
                if self.sink_failed:  # ... unless writing the outputs failed: that stops it
                    raise
                self.fail_unfinished(f"{type(exc).__name__}: {exc}")
            timings["execute"] = time.perf_counter() - t1

    def chunk_label(self, keys: Sequence[str]) -> str:
        """What a chunk holds, for a retry or a failure: ``jobs j0010..j0019 (10)``."""
        ids = [self.plan.jobs[self.first[k]].id for k in keys]
        return f"job {ids[0]}" if len(ids) == 1 else f"jobs {ids[0]}..{ids[-1]} ({len(ids)})"

    def close(self) -> None:
        """Finish the chunk being stored (an aborted sweep too) and stop the store thread."""
        if self.pool is not None:
            with contextlib.suppress(Exception):
                self.settle()
            self.pool.shutdown()

    def result(self) -> SweepResult:
        """The sweep's result as it stands (every job not finished is pending or failed)."""
        cache = self.cache
        return SweepResult(self.plan, metrics_frame(self.plan, self.metrics, self.status,
                                                    self.errors),
                           None, cache, self.setup.backend, self.setup.workers,
                           computed=self.computed, cached=self.cached,
                           interrupted=self.interrupted, timings=self.timings,
                           cache_corrupt=len(cache.corrupt) if cache is not None else 0,
                           memory=self.memory, signals_rule=self.rule,
                           run_warnings=self.warnings)

    # ------------------------------------------------------------------ job bookkeeping
    def finish(self, key: str, m: np.ndarray) -> None:
        """Every job of ``key`` finished with metrics ``m``."""
        st = DIVERGED if m[MET["diverged"]] == 1.0 else OK
        for idx in self.by_key[key]:
            self.metrics[idx] = m
            self.status[idx] = st

    def fail(self, keys: Sequence[str], text: str) -> None:
        """Every job of ``keys`` failed with the error ``text``."""
        for key in keys:
            for idx in self.by_key[key]:
                self.status[idx], self.errors[idx] = FAILED, text

    def fail_unfinished(self, text: str) -> None:
        """Every chunk not finished failed with the error ``text``."""
        for i, keys in enumerate(self.chunk_keys):
            if i not in self.done_chunks:
                self.fail(keys, text)

    def hand_on(self, keys: Sequence[str], signals: np.ndarray | None) -> None:
        """Give the signals of finished ``keys`` to ``on_signals`` (every job of each key)."""
        if self.on_signals is None or signals is None or self.plan.dec <= 0:
            return
        ts = time.perf_counter()
        pairs = [(idx, r) for r, key in enumerate(keys) for idx in self.by_key[key]]
        try:
            self.on_signals([p[0] for p in pairs], [p[1] for p in pairs], signals)
        except BaseException:
            self.sink_failed = True
            raise
        finally:
            self.timings["signals"] += time.perf_counter() - ts

    def store(self, keys: list[str], res: ChunkOutput) -> float:
        """Store a finished chunk in the cache (its signals if they are cached) -> seconds."""
        ts = time.perf_counter()
        assert self.cache is not None and res.metrics is not None
        self.cache.store(keys, res.metrics, res.signals if self.cache_signals else None,
                         self.plan.dec)
        return time.perf_counter() - ts

    def settle(self) -> None:
        """Wait for the chunk being stored in the background (re-raises a cache error)."""
        if self.storing:
            self.timings["store"] += self.storing.pop().result()

    def on_chunk(self, i: int, res: ChunkOutput) -> None:
        """A chunk finished: record its jobs, store it in the cache and hand its signals on.

        With signals to cache, the store runs in a thread of its own while the signals are
        handed on and the next chunk computes; it is waited for when the next chunk finishes
        (one in flight) and at the end. Its jobs count as computed at once.
        """
        ts = time.perf_counter()
        keys = self.chunk_keys[i]
        self.done_chunks.add(i)
        self.timings["kernel"] += res.kernel_s
        if res.error is not None or res.metrics is None:
            self.fail(keys, res.error or "no result")
        else:
            if (self.keep_signals and not self.cache_signals and res.signals is not None
                    and self.plan.dec > 0):
                self.memory.update((key, res.signals[r]) for r, key in enumerate(keys))
            if self.pool is not None:
                self.settle()
                self.storing.append(self.pool.submit(self.store, keys, res))
            elif self.cache is not None:
                self.timings["store"] += self.store(keys, res)
            self.hand_on(keys, res.signals)
            for r, key in enumerate(keys):
                self.finish(key, res.metrics[r])
            self.computed += len(keys)
        self.timings["writes"] += time.perf_counter() - ts
        self.bar.advance(sum(len(self.by_key[k]) for k in keys))


def check_cache_dir(path: Path) -> None:
    """Refuse a job cache folder that is a file or cannot be created, before anything is
    written (the cache itself is opened once the output folder exists)."""
    import os

    if path.exists() or path.is_symlink():
        if not path.is_dir():
            raise EmaError(f"--cache-dir '{path}' is a file; expected a folder (new or a job "
                           "cache)")
        if not os.access(path, os.W_OK | os.X_OK):
            raise EmaError(f"--cache-dir '{path}' is not writable; expected a writable folder")
        return
    parent = next((p for p in path.absolute().parents if p.exists()), None)
    if parent is None:
        return
    if not parent.is_dir():
        raise EmaError(f"--cache-dir '{path}' cannot be created: '{parent}' is a file, not a "
                       "folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise EmaError(f"--cache-dir '{path}' cannot be created: '{parent}' is not writable")


def _lookup(cache: JobCache | None, by_key: dict[str, list[int]], force: bool, dec: int,
            n_out: int, finish: Callable[[str, np.ndarray], None],
            hand_on: Callable[[Sequence[str], np.ndarray], None],
            n_signals: int = N_SIGNALS) -> list[str]:
    """Finish the jobs the cache holds intact (metrics, and signals if ``dec`` > 0), handing
    their signals on in batches; returns the keys still to compute."""
    found = {} if force or cache is None else cache.lookup(by_key)
    pending = [key for key in by_key if key not in found]
    if dec <= 0:
        for key, m in found.items():
            finish(key, m)
        return pending
    assert cache is not None or not found
    keys = list(found)
    step = max(1, CACHED_SIGNAL_BATCH_BYTES // (n_out * n_signals * 8))
    for a in range(0, len(keys), step):
        batch = keys[a:a + step]
        sigs = (cache.load_signals_many(batch, dec, n_out, n_signals) if cache is not None
                else {})
        ok = [key for key in batch if key in sigs]
        pending += [key for key in batch if key not in sigs]
        for key in ok:
            finish(key, found[key])
        if ok:
            hand_on(ok, np.stack([sigs[key] for key in ok]))
    return pending


def _corrupt_warning(cache: JobCache) -> str:
    """One line: how many damaged cache entries were found (recomputed), with an example."""
    n = len(cache.corrupt)
    key, what = next(iter(cache.corrupt.items()))
    return (f"job cache '{cache.root}': {n} damaged entr{'y' if n == 1 else 'ies'} not used "
            f"and recomputed (e.g. {key}: {what})")

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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.config.study import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.progress import announce_size
from ema_cli.sim.runner import check_memory
from ema_cli.sim.tables import MET, METRICS, N_METRICS, N_SIGNALS, SIGNALS
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
from ema_cli.sweep.plan import Job, Plan, plan_sweep

OK, DIVERGED, FAILED, PENDING = "ok", "diverged", "failed", "pending"
"""Job states: finished (ok or diverged), failed (error text in the manifest), not run."""
PROGRESS_REFRESH_PER_S = 4  # progress bar refresh rate [1/s]
CACHED_SIGNAL_BATCH_BYTES = 64 * 2**20  # cached signals read (and handed on) at a time [bytes]
JOB_COLUMN, TIME_COLUMN = "job", "t_s"
"""The job-id and time columns of a sweep's signals table (``signals.parquet``)."""

OnSignals = Callable[[Sequence[int], Sequence[int], np.ndarray], None]
"""``on_signals(jobs, rows, signals)``: job ``jobs[i]`` (index) recorded ``signals[rows[i]]``
(SI, [n_out, N_SIGNALS])."""


@dataclass
class SweepResult:
    """The outcome of a sweep.

    ``metrics``: one row per job — ``job`` (id), ``label``, ``status`` (ok | diverged | failed
    | pending), the swept values in the paper's units (see ``plan.axes`` for the columns), every
    simulator metric in edge units (``sim.tables``), the content hash ``key`` and the ``error``
    text of a failed job. ``folder`` is the output folder and ``signals_file`` the signals table
    written there (None if nothing was written; the report layer sets them). ``cache`` is the
    job cache (None: none was used). ``signals_rule`` says whether the recorded signals went
    into the cache (``sweep.cache.signals_rule``; None: nothing recorded or no cache); the
    signals of computed jobs not cached are kept in ``memory`` unless the caller streamed them
    to a file (``keep_signals`` False). ``cache_corrupt`` counts the cache entries found
    damaged, not used and recomputed (the warning is in ``run_warnings``, shown with the
    plan's in ``warnings``). ``timings`` are wall seconds: plan, lookup, warm, execute, kernel
    (summed over workers), store (cache writes), signals (the ``on_signals`` hook, i.e.
    streaming signals.parquet as chunks finish: converting the signals to columns and waiting
    for the encoder thread; it runs alongside the cache writes), writes (handling finished
    chunks: both of those, as the sweep waited for them), outputs, total.
    """

    plan: Plan
    metrics: pd.DataFrame
    folder: Path | None
    cache: JobCache | None
    backend: str
    workers: int
    computed: int
    cached: int
    interrupted: bool = False
    timings: dict[str, float] = field(default_factory=dict)
    figures: list[Path] = field(default_factory=list)
    pending: Any = None  # figures still being drawn (report.sweep_report.finish_sweep)
    signals_file: Path | None = None
    cache_corrupt: int = 0
    memory: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    signals_rule: SignalsRule | None = None
    run_warnings: list[str] = field(default_factory=list)

    @property
    def jobs(self) -> list[Job]:
        """The jobs, in metrics-table order."""
        return self.plan.jobs

    @property
    def warnings(self) -> list[str]:
        """What the user should be told: the plan's warnings, then the run's (damaged cache
        entries)."""
        return [*self.plan.warnings, *self.run_warnings]

    @property
    def signals_cached(self) -> bool:
        """True if the recorded signals of computed jobs were stored in the job cache."""
        return self.signals_rule is not None and self.signals_rule.cache

    def counts(self) -> dict[str, int]:
        """Jobs per status."""
        s = self.metrics["status"]
        return {k: int((s == k).sum()) for k in (OK, DIVERGED, FAILED, PENDING)}

    def _job(self, job: str | int) -> Job:
        if isinstance(job, int | np.integer):
            return self.plan.jobs[int(job)]
        for j in self.plan.jobs:
            if j.id == job:
                return j
        raise KeyError(f"no job {job!r} in this sweep")

    def signals(self, job: str | int) -> np.ndarray:
        """SI signals[n_out, N_SIGNALS] of one job (columns: ``sim.tables.SIGNALS``).

        From memory or the job cache (bit for bit what the kernel recorded), else from
        ``signals_file`` (edge units converted back: equal to within rounding; the way back for
        the jobs whose signals were not cached, see ``signals_rule``).
        """
        j = self._job(job)
        if self.plan.dec <= 0:
            raise EmaError("this sweep recorded no time series (outputs.timeseries and "
                           "outputs.per_job_csv are false and no overlay figures were asked for)")
        sig = self.memory.get(j.key)
        if sig is None and self.cache is not None:
            sig = self.cache.load_signals(j.key, self.plan.dec)
        if sig is None and self.signals_file is not None:
            ts = read_timeseries(self.signals_file, j.id)
            sig = np.stack([ts[c.edge].to_numpy() / c.factor for c in SIGNALS], axis=1)
        if sig is None:
            raise EmaError(f"job {j.id} ({j.label}) has no recorded time series "
                           f"(status {self.metrics['status'].iloc[j.index]})")
        return sig

    def timeseries(self, job: str | int) -> pd.DataFrame:
        """Decimated time series of one job in edge units, ``t_s`` first (like ema simulate);
        read from ``signals_file`` once it is written."""
        j = self._job(job)
        if self.signals_file is not None:
            return read_timeseries(self.signals_file, j.id)
        sig = self.signals(j.index)
        data = {TIME_COLUMN: np.arange(sig.shape[0]) * (self.plan.dec * self.plan.dt)}
        for k, c in enumerate(SIGNALS):
            data[c.edge] = sig[:, k] * c.factor
        return pd.DataFrame(data)


def read_timeseries(path: Path, job_id: str) -> pd.DataFrame:
    """One job's rows of a signals table (``t_s`` and every signal, edge units), in time order.

    Reads only the row groups whose statistics may hold ``job_id``.
    """
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path, columns=[TIME_COLUMN, *(c.edge for c in SIGNALS)],
                              filters=[(JOB_COLUMN, "=", job_id)])
    except (OSError, ValueError) as exc:  # pyarrow's errors derive from these
        raise EmaError(f"cannot read the signals table '{path}': {exc}", 1) from None
    if table.num_rows == 0:
        raise EmaError(f"the signals table '{path}' has no rows for job {job_id}", 1)
    return table.to_pandas()


def metrics_frame(plan: Plan, metrics: np.ndarray, status: Sequence[str],
                  errors: Sequence[str]) -> pd.DataFrame:
    """The metrics table: ids, labels, status, swept values, metrics (edge units), key, error."""
    rows: dict[str, Any] = {
        "job": [j.id for j in plan.jobs],
        "label": [j.label for j in plan.jobs],
        "status": list(status),
    }
    for info in plan.axes:
        for c in info.columns:
            rows[c] = [j.values.get(c, np.nan) for j in plan.jobs]
    for k, c in enumerate(METRICS):
        rows[c.edge] = metrics[:, k] * c.factor
    rows["key"] = [j.key for j in plan.jobs]
    rows["error"] = list(errors)
    df = pd.DataFrame(rows)
    df["diverged"] = df["status"] == DIVERGED
    return df


class _Progress:
    """A rich progress bar with ETA (or nothing when ``enabled`` is False)."""

    def __init__(self, total: int, enabled: bool, label: str) -> None:
        from ema_cli.progress import report

        self.bar = None
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
    timings: dict[str, float] = dict.fromkeys(
        ("lookup", "warm", "execute", "kernel", "store", "signals", "writes"), 0.0)
    if not isinstance(plan, Plan):
        plan = plan_sweep(plan, base_dir, source)
    cfg = plan.cfg
    reference = plan.reference if plan.reference is not None else plan.signal
    timings["plan"] = time.perf_counter() - t_start
    workers = resolve_workers(n_jobs if n_jobs is not None else cfg.parallel.n_jobs)
    backend = resolve_backend(backend or cfg.parallel.backend, workers)
    scheduler = scheduler or cfg.parallel.scheduler
    if backend == "dask":
        check_dask(scheduler)
    n_out_plan = plan.n_steps // plan.dec + 1 if plan.dec > 0 else 0
    if n_out_plan > 0 and plan.jobs:  # one chunk's recording must fit: refused before any write
        size = chunk_sizes(plan.n_unique, plan.n_steps, workers, backend, n_out_plan,
                           chunk_size or cfg.parallel.chunk_size)[0]
        check_memory(size, n_out_plan, 0)
    if cache_dir is not None:
        check_cache_dir(Path(cache_dir))
    if on_start is not None:  # first: a bad output folder is reported before anything is made
        on_start(plan)
    cache: JobCache | None = None

    n = len(plan.jobs)
    n_out = plan.n_steps // plan.dec + 1 if plan.dec > 0 else 0
    rule = (signals_rule(plan.n_steps, n_out, workers)
            if n_out > 0 and cache_dir is not None else None)
    cache_signals = rule is not None and rule.cache
    metrics = np.full((n, N_METRICS), np.nan)
    status = [PENDING] * n
    errors = [""] * n
    memory: dict[str, np.ndarray] = {}
    by_key: dict[str, list[int]] = {}
    for j in plan.jobs:
        by_key.setdefault(j.key, []).append(j.index)
    first = {key: idxs[0] for key, idxs in by_key.items()}
    computed = cached = 0
    sink_failed = False
    run_warnings: list[str] = []

    def finish(key: str, m: np.ndarray) -> None:
        st = DIVERGED if m[MET["diverged"]] == 1.0 else OK
        for idx in by_key[key]:
            metrics[idx] = m
            status[idx] = st

    def hand_on(keys: Sequence[str], signals: np.ndarray | None) -> None:
        """Give the signals of finished ``keys`` to ``on_signals`` (every job of each key)."""
        nonlocal sink_failed
        if on_signals is None or signals is None or plan.dec <= 0:
            return
        ts = time.perf_counter()
        pairs = [(idx, r) for r, key in enumerate(keys) for idx in by_key[key]]
        try:
            on_signals([p[0] for p in pairs], [p[1] for p in pairs], signals)
        except BaseException:
            sink_failed = True
            raise
        finally:
            timings["signals"] += time.perf_counter() - ts

    def store(keys: list[str], res: ChunkOutput) -> float:
        """Store a finished chunk in the cache (its signals if ``cache_signals``) -> seconds
        taken."""
        ts = time.perf_counter()
        assert cache is not None and res.metrics is not None
        cache.store(keys, res.metrics, res.signals if cache_signals else None, plan.dec)
        return time.perf_counter() - ts

    def settle() -> None:
        """Wait for the chunk being stored in the background (re-raises a cache error)."""
        if storing:
            timings["store"] += storing.pop().result()

    def on_chunk(i: int, res: ChunkOutput) -> None:
        """A chunk finished: record its jobs, store it in the cache and hand its signals on.

        With signals to cache, the store runs in a thread of its own while the signals are
        handed on and the next chunk computes; it is waited for when the next chunk finishes
        (one in flight) and at the end. Its jobs count as computed at once.
        """
        nonlocal computed
        ts = time.perf_counter()
        keys = chunk_keys[i]
        done_chunks.add(i)
        timings["kernel"] += res.kernel_s
        if res.error is not None or res.metrics is None:
            for key in keys:
                for idx in by_key[key]:
                    status[idx] = FAILED
                    errors[idx] = res.error or "no result"
        else:
            if keep_signals and not cache_signals and res.signals is not None and plan.dec > 0:
                memory.update((key, res.signals[r]) for r, key in enumerate(keys))
            if pool is not None:
                settle()
                storing.append(pool.submit(store, keys, res))
            elif cache is not None:
                timings["store"] += store(keys, res)
            hand_on(keys, res.signals)
            for r, key in enumerate(keys):
                finish(key, res.metrics[r])
            computed += len(keys)
        timings["writes"] += time.perf_counter() - ts
        bar.advance(sum(len(by_key[k]) for k in keys))

    chunk_keys: list[list[str]] = []
    done_chunks: set[int] = set()
    bar = _Progress(0, False, "")
    pool: ThreadPoolExecutor | None = None
    storing: list[Future[float]] = []  # the chunk being stored in the background (one at most)
    interrupted = aborted = False
    try:
        cache = JobCache(cache_dir) if cache_dir is not None else None
        if cache is not None and cache_signals:
            pool = ThreadPoolExecutor(1, thread_name_prefix="ema-cache-store")
        t0 = time.perf_counter()
        pending = _lookup(cache, by_key, force, plan.dec, n_out, finish, hand_on)
        pending.sort(key=first.__getitem__)
        announce_size(len(pending), plan.n_steps, workers)
        cached = len(by_key) - len(pending)
        if cache is not None and cache.corrupt:
            run_warnings.append(_corrupt_warning(cache))
        timings["lookup"] = time.perf_counter() - t0 - timings["signals"]

        sizes = chunk_sizes(len(pending), plan.n_steps, workers, backend, n_out,
                            chunk_size or cfg.parallel.chunk_size)
        bounds = np.cumsum([0, *sizes])
        chunk_keys = [pending[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
        chunks = [plan.P([plan.jobs[first[k]] for k in keys]) for keys in chunk_keys]
        label = f"{cfg.name}: {len(pending)} to run, {cached} cached"
        bar = _Progress(sum(len(by_key[k]) for k in pending), progress, label)
        with bar:
            if chunks and backend != "dask":
                timings["warm"] = warm_kernel(reference, plan.dt, 1)  # the prange kernel
            t1 = time.perf_counter()
            try:
                execute(chunks, reference, plan.dt, plan.n_steps, plan.dec, backend, workers,
                        on_chunk, scheduler)
                tw = time.perf_counter()
                settle()
                timings["writes"] += time.perf_counter() - tw
            except (KeyboardInterrupt, EmaError):
                raise
            except Exception as exc:  # a worker died: unfinished chunks are marked failed
                if sink_failed:  # ... unless writing the outputs failed: that stops the sweep
                    raise
                text = f"{type(exc).__name__}: {exc}"
                for i, keys in enumerate(chunk_keys):
                    if i not in done_chunks:
                        for key in keys:
                            for idx in by_key[key]:
                                status[idx], errors[idx] = FAILED, text
            timings["execute"] = time.perf_counter() - t1
    except KeyboardInterrupt:
        interrupted = aborted = True
        raise
    except BaseException:
        aborted = True
        raise
    finally:
        if pool is not None:  # an aborted sweep: the chunk being stored is finished first
            with contextlib.suppress(Exception):
                settle()
            pool.shutdown()
        result = SweepResult(plan, metrics_frame(plan, metrics, status, errors), None, cache,
                             backend, workers, computed=computed, cached=cached,
                             interrupted=interrupted, timings=timings,
                             cache_corrupt=len(cache.corrupt) if cache is not None else 0,
                             memory=memory, signals_rule=rule, run_warnings=run_warnings)
        if on_finish is not None:
            on_finish(result, aborted)
        timings["total"] = time.perf_counter() - t_start
    return result


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
            hand_on: Callable[[Sequence[str], np.ndarray], None]) -> list[str]:
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
    step = max(1, CACHED_SIGNAL_BATCH_BYTES // (n_out * N_SIGNALS * 8))
    for a in range(0, len(keys), step):
        batch = keys[a:a + step]
        sigs = cache.load_signals_many(batch, dec, n_out) if cache is not None else {}
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

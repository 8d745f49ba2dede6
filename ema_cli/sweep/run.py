"""The sweep runner: plan, look up the cache, execute what is missing (``compute_sweep``).

``compute_sweep`` returns a :class:`SweepResult`: the metrics table (one row per job) and
access to each job's decimated time series. It writes nothing but the job cache; the output
folder is written by ``report.sweep_report.run_sweep`` (the library entry point of ``ema sweep``
and of the paper reproduction) through the ``on_start`` / ``on_finish`` hooks.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.config.schema import StudyConfig
from ema_cli.errors import EmaError
from ema_cli.sim.tables import MET, METRICS, N_METRICS, SIGNALS
from ema_cli.sweep.cache import JobCache
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


@dataclass
class SweepResult:
    """The outcome of a sweep.

    ``metrics``: one row per job — ``job`` (id, also the time-series file name), ``label``,
    ``status`` (ok | diverged | failed | pending), the swept values in the paper's units (see
    ``plan.axes`` for the columns), every simulator metric in edge units (``sim.tables``), the
    content hash ``key`` and the ``error`` text of a failed job. ``folder`` is the output folder
    (None if nothing was written; the report layer sets it). ``timings`` are wall seconds:
    plan, lookup, warm, execute, kernel (summed over workers), store, outputs, total.
    """

    plan: Plan
    metrics: pd.DataFrame
    folder: Path | None
    cache: JobCache
    backend: str
    workers: int
    computed: int
    cached: int
    interrupted: bool = False
    timings: dict[str, float] = field(default_factory=dict)
    figures: list[Path] = field(default_factory=list)

    @property
    def jobs(self) -> list[Job]:
        """The jobs, in metrics-table order."""
        return self.plan.jobs

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
        """SI signals[n_out, N_SIGNALS] of one job (columns: ``sim.tables.SIGNALS``)."""
        j = self._job(job)
        if self.plan.dec <= 0:
            raise EmaError("this sweep recorded no time series (outputs.timeseries is false "
                           "and no overlay figures were asked for)")
        sig = self.cache.load_signals(j.key, self.plan.dec)
        if sig is None:
            raise EmaError(f"job {j.id} ({j.label}) has no recorded time series "
                           f"(status {self.metrics['status'].iloc[j.index]})")
        return sig

    def timeseries(self, job: str | int) -> pd.DataFrame:
        """Decimated time series of one job in edge units, ``t_s`` first (like ema simulate)."""
        sig = self.signals(job)
        data = {"t_s": np.arange(sig.shape[0]) * (self.plan.dec * self.plan.dt)}
        for k, c in enumerate(SIGNALS):
            data[c.edge] = sig[:, k] * c.factor
        return pd.DataFrame(data)


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
        self.bar = None
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
    cfg: StudyConfig,
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
    on_finish: Callable[[SweepResult, bool], None] | None = None,
) -> SweepResult:
    """Run every job of a sweep (finished ones from the cache) and return the result.

    cfg        validated StudyConfig (``load_config(path, overrides, StudyConfig)``)
    n_jobs     workers; None: ``cfg.parallel.n_jobs`` (None there: all cores); the dask
               backend uses every thread of the cluster instead
    backend    auto | loky | threads | dask; None: ``cfg.parallel.backend``
    force      recompute every job even if it is cached
    progress   show a progress bar with ETA on stderr
    scheduler  dask scheduler address (default ``cfg.parallel.scheduler``)
    chunk_size jobs per kernel call (default ``cfg.parallel.chunk_size``, else automatic)
    cache_dir  job cache folder (default ``results/.cache/sweep``)
    base_dir   folder relative CSV input profiles are looked up in (the config's folder)
    source     name of the config in error messages
    on_start   ``on_start(plan)``: called once the plan, backend and cache are ready, before
               any job runs (the report layer creates the output folder here)
    on_finish  ``on_finish(result, aborted)``: called when execution ends, also on Ctrl-C or
               an error (``aborted`` True, the result holds the finished jobs) before the
               exception propagates (the report layer writes the outputs here)

    Finished jobs are stored in the cache as each chunk completes; on Ctrl-C ``on_finish``
    runs and KeyboardInterrupt is re-raised. A job whose chunk raised is marked failed (error
    text in the result) and the sweep goes on. Writes nothing but the job cache.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    plan = plan_sweep(cfg, base_dir, source)
    timings["plan"] = time.perf_counter() - t_start
    workers = resolve_workers(n_jobs if n_jobs is not None else cfg.parallel.n_jobs)
    backend = resolve_backend(backend or cfg.parallel.backend, workers)
    scheduler = scheduler or cfg.parallel.scheduler
    if backend == "dask":
        check_dask(scheduler)
    cache = JobCache(cache_dir)
    if on_start is not None:
        on_start(plan)

    t0 = time.perf_counter()
    n = len(plan.jobs)
    n_out = plan.n_steps // plan.dec + 1 if plan.dec > 0 else 0
    metrics = np.full((n, N_METRICS), np.nan)
    status = [PENDING] * n
    errors = [""] * n
    by_key: dict[str, list[int]] = {}
    for j in plan.jobs:
        by_key.setdefault(j.key, []).append(j.index)

    def finish(key: str, m: np.ndarray) -> None:
        st = DIVERGED if m[MET["diverged"]] == 1.0 else OK
        for idx in by_key[key]:
            metrics[idx] = m
            status[idx] = st

    found = {} if force else cache.lookup(by_key)
    pending: list[str] = []
    for key in by_key:
        m = found.get(key)
        if m is not None and (plan.dec <= 0 or cache.has_signals(key, plan.dec, n_out)):
            finish(key, m)
        else:
            pending.append(key)
    cached = len(by_key) - len(pending)
    timings["lookup"] = time.perf_counter() - t0

    sizes = chunk_sizes(len(pending), plan.n_steps, workers, backend, n_out,
                        chunk_size or cfg.parallel.chunk_size)
    bounds = np.cumsum([0, *sizes])
    chunk_keys = [pending[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
    first = {key: idxs[0] for key, idxs in by_key.items()}
    chunks = [plan.P([plan.jobs[first[k]] for k in keys]) for keys in chunk_keys]
    done_chunks: set[int] = set()
    computed = 0
    timings.update(warm=0.0, execute=0.0, kernel=0.0, store=0.0)
    label = f"{cfg.name}: {len(pending)} to run, {cached} cached"
    bar = _Progress(sum(len(by_key[k]) for k in pending), progress, label)

    def on_chunk(i: int, res: ChunkOutput) -> None:
        nonlocal computed
        ts = time.perf_counter()
        keys = chunk_keys[i]
        if res.error is not None or res.metrics is None:
            for key in keys:
                for idx in by_key[key]:
                    status[idx] = FAILED
                    errors[idx] = res.error or "no result"
        else:
            cache.store(keys, res.metrics, res.signals, plan.dec)
            for r, key in enumerate(keys):
                finish(key, res.metrics[r])
            computed += len(keys)
        done_chunks.add(i)
        timings["kernel"] += res.kernel_s
        timings["store"] += time.perf_counter() - ts
        bar.advance(sum(len(by_key[k]) for k in keys))

    interrupted = aborted = False
    try:
        with bar:
            if chunks and backend != "dask":
                timings["warm"] = warm_kernel(plan.signal, plan.dt, 1)  # the prange kernel
            t1 = time.perf_counter()
            try:
                execute(chunks, plan.signal, plan.dt, plan.n_steps, plan.dec, backend, workers,
                        on_chunk, scheduler)
            except (KeyboardInterrupt, EmaError):
                raise
            except Exception as exc:  # a worker died: unfinished chunks are marked failed
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
        result = SweepResult(plan, metrics_frame(plan, metrics, status, errors), None, cache,
                             backend, workers, computed=computed, cached=cached,
                             interrupted=interrupted, timings=timings)
        if on_finish is not None:
            on_finish(result, aborted)
        timings["total"] = time.perf_counter() - t_start
    return result

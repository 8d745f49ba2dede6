"""A sweep's outcome: the metrics table (one row per job), the job states and each job's
recorded signals (from memory, the job cache or the signals table)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ema_cli.errors import EmaError
from ema_cli.sim.tables import METRICS, SIGNALS
from ema_cli.sweep.cache import JobCache, SignalsRule
from ema_cli.sweep.plan import Job, Plan

OK, DIVERGED, FAILED, PENDING = "ok", "diverged", "failed", "pending"
"""Job states: finished (ok or diverged), failed (error text in the manifest), not run."""
JOB_COLUMN, TIME_COLUMN = "job", "t_s"
"""The job-id and time columns of a sweep's signals table (``signals.parquet``)."""

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
        """SI signals[n_out, n] of one job (columns: the first ``plan.n_signals`` of
        ``sim.tables.SIGNALS``).

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
            sig = np.stack([ts[c.edge].to_numpy() / c.factor
                            for c in SIGNALS[:self.plan.n_signals]], axis=1)
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
        for k, c in enumerate(SIGNALS[:sig.shape[1]]):
            data[c.edge] = sig[:, k] * c.factor
        return pd.DataFrame(data)


def read_timeseries(path: Path, job_id: str) -> pd.DataFrame:
    """One job's rows of a signals table (``t_s`` and every signal, edge units), in time order.

    Reads only the row groups whose statistics may hold ``job_id``.
    """
    import pyarrow.parquet as pq

    try:
        names = set(pq.read_schema(path).names)  # the signals the sweep recorded
        table = pq.read_table(path, columns=[TIME_COLUMN, *(c.edge for c in SIGNALS
                                                            if c.edge in names)],
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

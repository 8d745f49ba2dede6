"""``api.sweep``: a nonlinearity / parameter sweep, as ``ema sweep`` runs it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ema_cli.api._inputs import (
    ConfigSource,
    Overrides,
    base_dir,
    folder_arg,
    override_pairs,
    source_name,
)
from ema_cli.api.simulation import signal_column
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.sweep.run import SweepResult


@dataclass
class Sweep:
    """A finished sweep: ``result`` is ``sweep.run.SweepResult``.

    ``metrics``: one row per job (id, label, status, swept values, every metric in edge units).
    Time series are there when the sweep records them (``outputs.timeseries`` true, the
    default).
    """

    result: SweepResult
    overrides: list[tuple[str, Any]] = field(default_factory=list)

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per job, edge units with the unit in each column name (metrics.csv)."""
        return self.result.metrics

    @property
    def jobs(self) -> list[str]:
        """The job ids, in metrics order."""
        return [j.id for j in self.result.plan.jobs]

    @property
    def t(self) -> np.ndarray:
        """The recorded times [s] (the same for every job)."""
        import numpy as np

        plan = self.result.plan
        if plan.dec <= 0:
            raise EmaError("this sweep recorded no time series (outputs.timeseries is false)")
        return np.arange(plan.n_steps // plan.dec + 1) * (plan.dec * plan.dt)

    def signal(self, name: str, job: str | int = 0) -> np.ndarray:
        """One recorded signal of one job (id or index) in its edge unit, at :attr:`t`."""
        from ema_cli.sim.tables import SIGNALS

        col = signal_column(name)
        if isinstance(job, bool) or not isinstance(job, str | int):
            raise EmaError(f"job: expected a job id such as {self.jobs[0]!r} or an index, got "
                           f"{job!r}")
        if isinstance(job, int) and not 0 <= job < len(self.jobs):
            raise EmaError(f"job index {job} is out of range: this sweep has {len(self.jobs)} "
                           f"jobs (0..{len(self.jobs) - 1})")
        try:
            sig = self.result.signals(job)
        except KeyError as exc:
            raise EmaError(str(exc.args[0])) from None
        return sig[:, SIGNALS.index(col)] * col.factor

    def to_pandas(self, form: str = "long") -> pd.DataFrame:
        """Every finished job's signals with its id and swept values: ``long`` (``job``, swept
        values, ``t_s``, ``signal``, ``value``) or ``wide`` (one row per job and time, one
        column per signal, units in the names)."""
        import pandas as pd

        from ema_cli.sweep.run import DIVERGED, OK

        if form not in ("wide", "long"):
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        df = self.metrics
        swept = [c for info in self.result.plan.axes for c in info.columns if c in df.columns]
        frames = []
        for i, job in enumerate(self.jobs):
            if df["status"].iloc[i] not in (OK, DIVERGED):
                continue
            ts = self.result.timeseries(job)
            ts.insert(0, "job", job)
            for k, c in enumerate(swept):
                ts.insert(1 + k, c, df[c].iloc[i])
            frames.append(ts)
        if not frames:
            raise EmaError("no finished job recorded a time series")
        wide = pd.concat(frames, ignore_index=True)
        if form == "wide":
            return wide
        return wide.melt(id_vars=["job", *swept, "t_s"], var_name="signal", value_name="value")

    def plot(self, kind: str = "metrics") -> list[Figure]:
        """The sweep's figures as ``ema sweep`` draws them: ``metrics`` (metrics vs the swept
        magnitude, one per axis), ``errors`` or ``response`` (overlays vs time)."""
        from ema_cli.report.sweep_report import sweep_figures

        if kind not in ("metrics", "errors", "response"):
            raise EmaError(f"kind must be metrics, errors or response, got {kind!r}")
        return [fig for _, fig in sweep_figures(self.result, kinds=(kind,))]

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema sweep`` writes (metrics.csv, time series, figures, summary,
        manifest) -> the folder (new or empty if given)."""
        from ema_cli.report.sweep_report import save_sweep

        return save_sweep(self.result, folder_arg(folder),
                          self.overrides)


def _parallel_args(n_jobs: Any, backend: Any, force: Any, progress: Any, cache_dir: Any) -> None:
    """The parallel arguments of ``sweep`` and ``sensitivity``, checked (EmaError naming the
    argument)."""
    from ema_cli.api._inputs import choice_arg, flag_arg, number_arg, path_arg
    from ema_cli.limits import BACKENDS, MAX_WORKERS

    if n_jobs != -1:
        number_arg(n_jobs, "n_jobs", low=1, high=MAX_WORKERS, integer=True)
    choice_arg(backend, "backend", BACKENDS)
    flag_arg(force, "force")
    flag_arg(progress, "progress")
    path_arg(cache_dir, "cache_dir")


def sweep(config: ConfigSource, overrides: Overrides = None, *, n_jobs: int | None = None,
          backend: str | None = None, force: bool = False, progress: bool = False,
          cache_dir: str | Path | None = None) -> Sweep:
    """Run every job of a study config, as ``ema sweep CONFIG --set ...`` does, without
    writing an output folder (``.save()`` does). With ``cache_dir`` the jobs are cached there
    (finished ones are reused by later calls); without it nothing is written to disk and the
    recorded signals are kept in memory with the result.

    n_jobs, backend, force, progress   as the command's options
    """
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig
    from ema_cli.report.sweep_report import run_sweep

    _parallel_args(n_jobs, backend, force, progress, cache_dir)
    from ema_cli.api._inputs import check_sweep_steps

    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, StudyConfig)
    check_sweep_steps(cfg, source_name(config))
    from ema_cli.api._inputs import capped_jobs

    n_jobs = capped_jobs(n_jobs, cfg, backend)
    res = run_sweep(cfg, None, n_jobs, backend, force, progress,
                    cache_dir=Path(cache_dir) if cache_dir is not None else None,
                    base_dir=base_dir(config), source=source_name(config), overrides=pairs,
                    write=False)
    return Sweep(res, pairs)

"""``api.sweep``: a nonlinearity / parameter sweep, as ``ema sweep`` runs it."""

from __future__ import annotations

from collections.abc import Sequence
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

    from ema_cli.config.study import StudyConfig
    from ema_cli.sweep.plan import Plan
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
        k = SIGNALS.index(col)
        if k >= sig.shape[1]:
            raise EmaError(f"signal {name!r} is not recorded for this actuator")
        return sig[:, k] * col.factor

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

    def finish(self) -> None:
        """Wait for figures drawn in the background (``figures="background"``) and finish the
        folder (final manifest, finished mark); nothing to do otherwise."""
        from ema_cli.report.sweep_report import finish_sweep

        finish_sweep(self.result)

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema sweep`` writes (metrics.csv, time series, figures, summary,
        manifest) -> the folder (new or empty if given)."""
        from ema_cli.report.sweep_report import save_sweep

        return save_sweep(self.result, folder_arg(folder),
                          self.overrides)


def run_sweep(
    cfg: StudyConfig | Plan,
    out: Path | None = None,
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
    overrides: Sequence[tuple[str, Any]] = (),
    write: bool = True,
    reuse_finished: bool = False,
    figures: str = "draw",
) -> SweepResult:
    """The one route of a sweep: plan the config once (``sweep.plan.plan_sweep``: jobs,
    parameter rows, the reference sampled once), compute it (``sweep.run.compute_sweep``) and,
    when ``write``, stream it into its output folder (``report.sweep_report.SweepFolder``).

    cfg        a validated StudyConfig, or a Plan already made from one
    out        output folder; None: ``results/sweep/<name>/<stamp>_<hash>/``
    cache_dir  job cache; None: ``report.sweep_report.default_cache_dir(out)`` when writing,
               no cache otherwise
    write      False: write nothing (no folder, and no cache unless ``cache_dir`` is given);
               the recorded signals stay readable from the result (kept in memory)
    overrides, reuse_finished, figures   as ``SweepFolder``; the rest as ``compute_sweep``
    """
    from ema_cli.report.rundir import check_output
    from ema_cli.report.sweep_report import SweepFolder, default_cache_dir
    from ema_cli.sweep.plan import Plan, plan_sweep
    from ema_cli.sweep.run import compute_sweep

    sink = SweepFolder(out, overrides, figures, reuse_finished) if write else None
    if write and out is not None and not Path(out).is_dir():
        check_output(Path(out), "sweep")  # a file, or below one: refused before the cache is
    if cache_dir is None and write:
        cache_dir = default_cache_dir(out)
    plan = cfg if isinstance(cfg, Plan) else plan_sweep(cfg, base_dir, source)
    return compute_sweep(plan, n_jobs, backend, force, progress, scheduler=scheduler,
                         chunk_size=chunk_size, cache_dir=cache_dir,
                         on_start=sink.start if sink else None,
                         on_signals=sink.add if sink else None,
                         on_finish=sink.finish if sink else None,
                         keep_signals=not (write and plan.cfg.outputs.timeseries))


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


def plan(config: ConfigSource, overrides: Overrides = None) -> Plan:
    """The jobs a study config expands to, resolved (``sweep.plan.plan_sweep``: SI parameters,
    labels, cache keys, the reference), as ``ema show`` lists them; nothing runs but the
    baseline a relative axis needs."""
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig
    from ema_cli.sweep.plan import plan_sweep

    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, StudyConfig)
    _check(cfg)
    return plan_sweep(cfg, base_dir(config), source_name(config))


def sweep(config: ConfigSource, overrides: Overrides = None, *, n_jobs: int | None = None,
          backend: str | None = None, force: bool = False, progress: bool = False,
          cache_dir: str | Path | None = None, out: str | Path | None = None,
          write: bool = False, scheduler: str | None = None, figures: str = "draw") -> Sweep:
    """Run every job of a study config, as ``ema sweep CONFIG --set ...`` does. By default
    nothing is written (``.save()`` writes the folder): with ``cache_dir`` the jobs are cached
    there (finished ones are reused by later calls); without it the recorded signals are kept
    in memory with the result. ``write`` True (or ``out`` given): the command's output folder
    is written as the sweep runs (``out``, default a new one under results/sweep/; an
    unfinished run of the same sweep there is resumed) with the command's job cache. The
    work is estimated first (refused above ``limits``' cap) and the workers capped at the
    cores (a warning).

    n_jobs, backend, scheduler, force, progress   as the command's options
    figures  draw | none | background (drawn in a thread: call ``.finish()`` before exiting)
    """
    from ema_cli.api._inputs import capped_jobs, check_sweep_steps
    from ema_cli.config.loader import load_config
    from ema_cli.config.study import StudyConfig

    _parallel_args(n_jobs, backend, force, progress, cache_dir)
    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, StudyConfig)
    _check(cfg)
    check_sweep_steps(cfg, source_name(config))
    n_jobs = capped_jobs(n_jobs, cfg, backend)
    res = run_sweep(cfg, folder_arg(out), n_jobs, backend, force, progress,
                    scheduler=scheduler,
                    cache_dir=Path(cache_dir) if cache_dir is not None else None,
                    base_dir=base_dir(config), source=source_name(config), overrides=pairs,
                    write=write or out is not None, figures=figures)
    return Sweep(res, pairs)


def _check(cfg: Any) -> None:
    """Refuse an actuator description a sweep cannot run (``config.support``)."""
    from ema_cli.config.support import check_command

    check_command(cfg, "sweep")

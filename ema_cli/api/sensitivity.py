"""``api.sensitivity``: global sensitivity of the metrics to the factors (Morris or Sobol), as
``ema sensitivity`` runs it."""

from __future__ import annotations

from collections.abc import Callable, Sequence
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
from ema_cli.errors import EmaError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from ema_cli.config.sensitivity import SensitivityConfig
    from ema_cli.sensitivity.run import SensitivityResult


@dataclass
class Sensitivity:
    """A finished sensitivity study: ``result`` is ``sensitivity.run.SensitivityResult``.

    ``indices``: one row per (input, metric, factor) with S1, S1_conf, ST, ST_conf (Sobol) or
    mu_star, mu_star_conf, sigma, mu (Morris); ``metrics``: one row per simulation (input,
    design row, factor values, metrics in edge units); ``convergence``: the indices on the
    nested designs n/32 .. n.
    """

    result: SensitivityResult
    overrides: list[tuple[str, Any]] = field(default_factory=list)

    @property
    def indices(self) -> pd.DataFrame:
        """indices.csv."""
        return self.result.indices

    @property
    def metrics(self) -> pd.DataFrame:
        """One row per simulation: input, row, key, status, factor values, metrics."""
        return self.result.samples

    @property
    def convergence(self) -> pd.DataFrame:
        """convergence.csv: the indices on nested prefixes of the design (column ``n``)."""
        return self.result.convergence

    def ranking_text(self, input: str | None = None, metric: str | None = None,
                     top: int = 3) -> str:
        """The ``top`` factors of one input and metric with their index and its 95 %
        half-width, as the console prints them (``Kpp 0.41 ± 0.12, ...``)."""
        from ema_cli.sensitivity.analyze import index_text

        t = self.ranked(input, metric)
        return ", ".join(index_text(row, self.result.method) for _, row in t.head(top).iterrows())

    def imprecise(self, input: str | None = None, metric: str | None = None) -> list[str]:
        """The factors of one input and metric whose index is too imprecise to rank (its
        half-width over a fifth of it, or ST outside [0, 1]): ``sensitivity.analyze.imprecise``."""
        from ema_cli.sensitivity.analyze import imprecise

        return imprecise(self.ranked(input, metric), self.result.method)

    def ranked(self, input: str | None = None, metric: str | None = None) -> pd.DataFrame:
        """The indices of one input and metric (default: the first of each), most influential
        factor first (by ST, or mu* for Morris)."""
        from ema_cli.sensitivity.analyze import ranking

        names = [r.name for r in self.result.inputs]
        input = input or names[0]
        metric = metric or self.result.cfg.metrics[0]
        if input not in names:
            raise EmaError(f"input: no input {input!r}; this study has {', '.join(names)}")
        if metric not in self.result.cfg.metrics:
            raise EmaError(f"metric: {metric!r} was not analysed; expected one of "
                           f"{', '.join(self.result.cfg.metrics)}")
        ix = self.indices
        return ranking(ix[(ix["input"] == input) & (ix["metric"] == metric)], self.result.method)

    def ranking(self, input: str | None = None, metric: str | None = None) -> list[str]:
        """The factors, most influential first (by ST, or mu* for Morris), for one input and
        metric (default: the first of each)."""
        return [str(f) for f in self.ranked(input, metric)["factor"]]

    def to_pandas(self, form: str = "wide") -> pd.DataFrame:
        """The indices: ``wide`` (indices.csv) or ``long`` (input, metric, transform, factor,
        quantity, value)."""
        df = self.indices
        if form == "wide":
            return df
        if form != "long":
            raise EmaError(f"form must be 'wide' or 'long', got {form!r}")
        return df.melt(id_vars=["input", "metric", "transform", "factor"], var_name="quantity",
                       value_name="value").dropna(subset=["value"])

    def plot(self, kind: str = "indices") -> list[Figure]:
        """The figures ``ema sensitivity`` draws, one per input: ``indices`` (bar charts with
        confidence intervals) or ``convergence`` (the indices as n doubles)."""
        from ema_cli.report.sensitivity_report import convergence_figure, indices_figure

        if kind not in ("indices", "convergence"):
            raise EmaError(f"kind must be indices or convergence, got {kind!r}")
        draw = indices_figure if kind == "indices" else convergence_figure
        return [draw(self.result, r.name) for r in self.result.inputs]

    def save(self, folder: str | Path | None = None) -> Path:
        """Write the folder ``ema sensitivity`` writes -> the folder (new or empty if given)."""
        from ema_cli.report.sensitivity_report import save_sensitivity

        return save_sensitivity(self.result, folder_arg(folder), self.overrides)


def run_sensitivity(
    cfg: SensitivityConfig,
    out: Path | None = None,
    method: str | None = None,
    n: int | None = None,
    *,
    n_jobs: int | None = None,
    backend: str | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: bool = True,
    cache_dir: Path | None = None,
    base_dir: Path | None = None,
    source: str = "config",
    overrides: Sequence[tuple[str, Any]] = (),
    write: bool = True,
    reuse_finished: bool = False,
    log: Callable[[str], None] | None = None,
) -> SensitivityResult:
    """The one route of a sensitivity study: compute it (``sensitivity.run.compute_sensitivity``)
    and, when ``write``, have ``report.sensitivity_report`` write its folder (``write`` False:
    nothing is written, and no job cache unless ``cache_dir`` is given).

    out        output folder; None: ``results/sensitivity/<name>/<stamp>_<hash>/``. An
               existing folder is reused only if it holds an unfinished study of the same
               config, method and n
               (resumed: finished samples come from the job cache)
    cache_dir  job cache; None: ``report.sweep_report.default_cache_dir(out)`` when writing

    reuse_finished  ``out`` belongs to a run being resumed (``ema reproduce``): if it holds the
               finished study of these very inputs, it is kept as it is (the indices are
               recomputed from the job cache, nothing is written)

    On Ctrl-C the manifest says ``interrupted`` and the exception propagates; the finished
    samples are in the job cache for the rerun.
    """
    from ema_cli.report.rundir import FINISHED, check_output, finish_output
    from ema_cli.report.sensitivity_report import (
        COMMAND,
        fingerprint,
        finished_study,
        prepare_folder,
        write_manifest,
        write_outputs,
    )
    from ema_cli.report.sweep_report import default_cache_dir
    from ema_cli.sensitivity.run import compute_sensitivity, resolve_method

    reused = False
    if write:
        method, n = resolve_method(cfg, method, n)
        if cache_dir is None:
            cache_dir = default_cache_dir(out)
        fp = fingerprint(cfg, method, n, overrides)
        kept = reuse_finished and out is not None and finished_study(Path(out), fp)
        if kept or check_output(out, COMMAND, fp) == FINISHED:  # kept as it is: no writes
            write, reused = False, True

    def on_start(res: SensitivityResult) -> None:
        if write:
            prepare_folder(res, out, overrides)

    def on_finish(res: SensitivityResult, aborted: bool) -> None:
        if res.folder is None:
            return
        if aborted:
            write_manifest(res, overrides)
            return
        write_outputs(res, overrides)
        if res.complete:
            finish_output(res.folder)

    res = compute_sensitivity(cfg, method, n, n_jobs=n_jobs, backend=backend,
                              scheduler=scheduler, force=force, progress=progress,
                              cache_dir=cache_dir, base_dir=base_dir, source=source,
                              on_start=on_start, on_finish=on_finish, log=log)
    if reused:
        res.folder = Path(out) if out is not None else None
    return res


def sensitivity(config: ConfigSource, overrides: Overrides = None, *, method: str | None = None,
                n: int | None = None, n_jobs: int | None = None, backend: str | None = None,
                force: bool = False, progress: bool = False,
                cache_dir: str | Path | None = None, out: str | Path | None = None,
                write: bool = False, scheduler: str | None = None,
                log: Callable[[str], None] | None = None,
                on_progress: Callable[[str, int | None, int | None], None] | None = None
                ) -> Sensitivity:
    """Run a sensitivity study config (factors, metrics, inputs), as ``ema sensitivity CONFIG
    --method --n --set ...`` does. By default nothing is written (``.save()`` writes the
    folder); ``write`` True (or ``out`` given): the command's folder is written as the study
    runs (``out``, default a new one under results/sensitivity/; an unfinished study of the
    same inputs there is resumed) with the command's job cache.

    method   sobol | morris (default: the config's ``sensitivity.method``)
    n        Sobol base samples (a power of two) or Morris trajectories (default: the config's)
    cache_dir  a job cache to use (finished samples are reused by later calls); without it
             nothing is written to disk
    log      ``log(text)``: one line per input as it starts, and the size and time estimate
    on_progress  ``on_progress(stage, done, total)``: the stages and steps the command line
             shows (``ema_cli.progress.StageHook``), e.g. ("simulations", 4096, 98304)
    n_jobs, backend, scheduler, force, progress   as ``api.sweep``
    """
    from ema_cli.api._inputs import capped_jobs, check_sensitivity_steps, choice_arg, number_arg
    from ema_cli.api.study import _parallel_args
    from ema_cli.config.loader import load_config
    from ema_cli.config.sensitivity import SensitivityConfig

    _parallel_args(n_jobs, backend, force, progress, cache_dir)
    from ema_cli.api._inputs import callable_arg

    callable_arg(on_progress, "on_progress")
    choice_arg(method, "method", ("sobol", "morris"))
    number_arg(n, "n", low=1, integer=True)
    pairs = override_pairs(overrides)
    cfg = load_config(config, pairs, SensitivityConfig)
    from ema_cli.config.support import check_command

    check_command(cfg, "sensitivity")
    check_sensitivity_steps(cfg, method, n, source_name(config))
    n_jobs = capped_jobs(n_jobs, cfg, backend)
    from ema_cli.progress import hooked

    with hooked(on_progress, log):
        res = run_sensitivity(cfg, folder_arg(out), method, n, n_jobs=n_jobs, backend=backend,
                              scheduler=scheduler, force=force, progress=progress,
                              cache_dir=Path(cache_dir) if cache_dir is not None else None,
                              base_dir=base_dir(config), source=source_name(config),
                              overrides=pairs, write=write or out is not None, log=log)
    return Sensitivity(res, pairs)
